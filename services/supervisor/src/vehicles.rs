//! `skymesh_vehicle_*` gauges: what each configured vehicle's autopilot link
//! publishes (`VehicleState`, `VehicleStatus`), so Prometheus can alert on the
//! aircraft (battery, link, altitude), not only on processes.
//!
//! The supervisor never waits on these topics: it reads the newest sample of each
//! when `/metrics` is scraped ([`Subscriber::latest`]; the subscribers are
//! `set_newest_only` and never registered with the reactor), so a 50 Hz
//! `VehicleState` costs an idle supervisor no wake-up. Every gauge of every
//! vehicle in `supervisor.vehicles` is exported from the first scrape on, before
//! any sample (values unknown until then: NaN, link 0, mode `unknown`), so alert
//! rules see the series from the start.
//!
//! The same read feeds the web console (crate::console): each vehicle's authority,
//! its arbiter's recent events and command decisions, and the altitude/speed
//! history of its plot ([`VehicleLog`]), taken whenever `/metrics` is scraped or
//! the console asks.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use prometheus::core::{Collector, Desc};
use prometheus::proto::{self, LabelPair, Metric, MetricFamily, MetricType};
use skymesh_ipc_types::{
    topics, ArbiterEvent, AuthorityState, CommandAck, FlightMode, VehicleState, VehicleStatus,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, IpcError, Subscriber};

pub use crate::console::feed::VehicleLog;

/// A status older than this means the autopilot link stopped publishing (it
/// publishes on change and at least once a second): the link counts as down.
pub const STATUS_STALE: Duration = Duration::from_secs(3);

/// The prefix of every family here; services may not report names under it.
pub const PREFIX: &str = "skymesh_vehicle_";

/// The families: name, help.
pub const FAMILIES: [(&str, &str); 9] = [
    ("skymesh_vehicle_altitude_meters", "Altitude above home (VehicleState alt_rel_m); NaN until a position is known."),
    ("skymesh_vehicle_ground_speed_meters_per_second", "Horizontal speed over ground (north and east velocity); NaN until a position is known."),
    ("skymesh_vehicle_battery_remaining_ratio", "Battery charge left, 0..1; NaN when the autopilot does not know it."),
    ("skymesh_vehicle_battery_voltage_volts", "Battery voltage; NaN before the first status."),
    ("skymesh_vehicle_armed", "1 while the motors are armed (from the last status while the link is up), else 0."),
    ("skymesh_vehicle_mode", "1 for the vehicle's current flight mode, 0 for the others (`unknown` before the first status)."),
    ("skymesh_vehicle_link_up", "1 while the autopilot link reports autopilot heartbeats and its status is fresh (newer than 3 s), else 0."),
    ("skymesh_vehicle_telemetry_age_seconds", "Seconds since the newest VehicleState was published; NaN before the first."),
    ("skymesh_vehicle_status_age_seconds", "Seconds since the newest VehicleStatus was published; NaN before the first."),
];

/// The newest samples of one vehicle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Latest {
    pub state: Option<VehicleState>,
    pub status: Option<VehicleStatus>,
    pub authority: Option<AuthorityState>,
}

struct Ports {
    state: Subscriber<VehicleState>,
    status: Subscriber<VehicleStatus>,
    authority: Subscriber<AuthorityState>,
    /// Drained at each read; the log keeps the newest few.
    events: Subscriber<ArbiterEvent>,
    acks: Subscriber<CommandAck>,
}

impl Ports {
    /// Takes everything pending into `latest` and `log`.
    fn drain(&self, latest: &mut Latest, log: &mut VehicleLog) -> Result<(), IpcError> {
        if let Some(s) = self.state.latest()? {
            latest.state = Some(s);
            log.record(&s);
        }
        latest.status = self.status.latest()?.or(latest.status);
        latest.authority = self.authority.latest()?.or(latest.authority);
        while let Some(e) = self.events.try_recv()? {
            log.event(e);
        }
        while let Some(a) = self.acks.try_recv()? {
            log.ack(a);
        }
        Ok(())
    }
}

struct Inner {
    /// Per vehicle, once the bus is open.
    ports: Option<Vec<Ports>>,
    latest: Vec<Latest>,
    logs: Vec<VehicleLog>,
    /// A receive failure already logged (once, not per scrape).
    warned: bool,
}

/// The collector: configured vehicle ids, their subscribers and newest samples.
pub struct VehicleGauges {
    ids: Vec<u8>,
    inner: Mutex<Inner>,
}

impl std::fmt::Debug for VehicleGauges {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VehicleGauges")
            .field("ids", &self.ids)
            .finish()
    }
}

impl VehicleGauges {
    /// Gauges for `ids`; values unknown until [`VehicleGauges::attach`].
    pub fn new(ids: &[u8]) -> Self {
        VehicleGauges {
            ids: ids.to_vec(),
            inner: Mutex::new(Inner {
                ports: None,
                latest: vec![Latest::default(); ids.len()],
                logs: vec![VehicleLog::default(); ids.len()],
                warned: false,
            }),
        }
    }

    /// Subscribes to every vehicle's state, status, authority, arbiter events and
    /// command acks on `bus`.
    pub fn attach(&self, bus: &Bus) -> Result<(), IpcError> {
        let mut ports = Vec::with_capacity(self.ids.len());
        for &id in &self.ids {
            let mut state = bus.subscriber::<VehicleState>(&topics::vehicle_state(id))?;
            let mut status = bus.subscriber::<VehicleStatus>(&topics::vehicle_status(id))?;
            let mut authority = bus.subscriber::<AuthorityState>(&topics::vehicle_authority(id))?;
            let mut events = bus.subscriber::<ArbiterEvent>(&topics::vehicle_arbiter_events(id))?;
            let mut acks = bus.subscriber::<CommandAck>(&topics::vehicle_command_ack(id))?;
            // Read at scrape (or console) time: samples overwritten in between are
            // by design (the console shows the newest events and decisions only).
            state.set_newest_only();
            status.set_newest_only();
            authority.set_newest_only();
            events.set_newest_only();
            acks.set_newest_only();
            ports.push(Ports {
                state,
                status,
                authority,
                events,
                acks,
            });
        }
        self.lock().ports = Some(ports);
        Ok(())
    }

    /// Drops the subscribers (and with them their hold on the bus's node); the
    /// gauges keep the last values read.
    pub fn detach(&self) {
        self.lock().ports = None;
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes the pending samples into `latest` and the logs.
    fn drain(inner: &mut Inner) {
        let Inner {
            ports,
            latest,
            logs,
            warned,
        } = inner;
        if let Some(ports) = ports {
            for ((p, l), log) in ports.iter().zip(latest.iter_mut()).zip(logs.iter_mut()) {
                match p.drain(l, log) {
                    Ok(()) => {}
                    Err(e) if !*warned => {
                        *warned = true;
                        tracing::warn!(error = %e, "reading the vehicles' topics failed");
                    }
                    Err(_) => {}
                }
            }
        }
    }

    /// Takes the newest pending samples into `latest` and returns a copy.
    fn refresh(&self) -> Vec<Latest> {
        let mut inner = self.lock();
        Self::drain(&mut inner);
        inner.latest.clone()
    }

    /// Every vehicle with its newest samples and its log, read now (the console).
    pub fn snapshot(&self) -> Vec<(u8, Latest, VehicleLog)> {
        let mut inner = self.lock();
        Self::drain(&mut inner);
        self.ids
            .iter()
            .zip(&inner.latest)
            .zip(&inner.logs)
            .map(|((id, l), log)| (*id, *l, log.clone()))
            .collect()
    }

    /// The answer to command `command_id` of `source` for the vehicle at `idx`
    /// (of [`VehicleGauges::ids`]), if it has arrived (reads the topics now).
    pub fn find_ack(
        &self,
        idx: usize,
        source: skymesh_ipc_types::CommandSource,
        command_id: u32,
    ) -> Option<CommandAck> {
        let mut inner = self.lock();
        Self::drain(&mut inner);
        inner
            .logs
            .get(idx)?
            .acks
            .iter()
            .rev()
            .copied()
            .find(|a| a.source == source.to_wire() && a.command_id == command_id)
    }

    /// The configured vehicle ids, ascending.
    pub fn ids(&self) -> &[u8] {
        &self.ids
    }
}

fn label(name: &str, value: &str) -> LabelPair {
    let mut l = LabelPair::default();
    l.set_name(name.to_string());
    l.set_value(value.to_string());
    l
}

fn gauge(labels: Vec<LabelPair>, v: f64) -> Metric {
    let mut g = proto::Gauge::default();
    g.set_value(v);
    let mut m = Metric::from_label(labels);
    m.set_gauge(g);
    m
}

fn age_s(stamp_ns: u64, now_ns: u64) -> f64 {
    Duration::from_nanos(now_ns.saturating_sub(stamp_ns)).as_secs_f64()
}

/// The gauges of `vehicles` (`(id, newest samples)`) at `now_ns` (pure).
pub fn families(vehicles: &[(u8, Latest)], now_ns: u64) -> Vec<MetricFamily> {
    let mut metrics: Vec<Vec<Metric>> = vec![Vec::new(); FAMILIES.len()];
    for (id, l) in vehicles {
        let id_text = id.to_string();
        let v = || vec![label("vehicle", &id_text)];
        let position = l.state.filter(|s| s.position_valid != 0);
        let fresh_status = l
            .status
            .filter(|s| age_s(s.header.stamp_ns, now_ns) <= STATUS_STALE.as_secs_f64());
        let link_up = fresh_status.is_some_and(|s| s.link_up != 0);
        let status_while_up = fresh_status.filter(|_| link_up);
        let values = [
            position.map_or(f64::NAN, |s| f64::from(s.alt_rel_m)),
            position.map_or(f64::NAN, |s| {
                f64::from(s.vel_ned_mps[0]).hypot(f64::from(s.vel_ned_mps[1]))
            }),
            l.status
                .filter(|s| (0..=100).contains(&s.battery_remaining_pct))
                .map_or(f64::NAN, |s| f64::from(s.battery_remaining_pct) / 100.0),
            l.status
                .map_or(f64::NAN, |s| f64::from(s.battery_voltage_v)),
            f64::from(u8::from(status_while_up.is_some_and(|s| s.armed != 0))),
        ];
        for (i, value) in values.into_iter().enumerate() {
            metrics[i].push(gauge(v(), value));
        }
        let mode = l.status.map_or(FlightMode::Unknown, |s| s.flight_mode());
        for m in FlightMode::ALL {
            let labels = vec![label("vehicle", &id_text), label("mode", m.as_str())];
            metrics[5].push(gauge(labels, f64::from(u8::from(*m == mode))));
        }
        metrics[6].push(gauge(v(), f64::from(u8::from(link_up))));
        metrics[7].push(gauge(
            v(),
            l.state
                .map_or(f64::NAN, |s| age_s(s.header.stamp_ns, now_ns)),
        ));
        metrics[8].push(gauge(
            v(),
            l.status
                .map_or(f64::NAN, |s| age_s(s.header.stamp_ns, now_ns)),
        ));
    }
    if vehicles.is_empty() {
        return Vec::new();
    }
    FAMILIES
        .iter()
        .zip(metrics)
        .map(|((name, help), m)| {
            let mut mf = MetricFamily::default();
            mf.set_name((*name).to_string());
            mf.set_help((*help).to_string());
            mf.set_field_type(MetricType::GAUGE);
            mf.set_metric(m);
            mf
        })
        .collect()
}

/// The registry's handle on shared [`VehicleGauges`] (the supervisor attaches the
/// bus to them after the registry exists).
#[derive(Debug)]
pub struct Collect {
    gauges: Arc<VehicleGauges>,
    /// One per family: the registry tells collectors apart by their descriptions.
    descs: Vec<Desc>,
}

impl Collect {
    pub fn new(gauges: Arc<VehicleGauges>) -> prometheus::Result<Self> {
        let descs = FAMILIES
            .iter()
            .map(|(name, help)| {
                let mut labels = vec!["vehicle".to_string()];
                if *name == "skymesh_vehicle_mode" {
                    labels.push("mode".to_string());
                }
                Desc::new(
                    (*name).to_string(),
                    (*help).to_string(),
                    labels,
                    Default::default(),
                )
            })
            .collect::<prometheus::Result<_>>()?;
        Ok(Collect { gauges, descs })
    }
}

impl Collector for Collect {
    fn desc(&self) -> Vec<&Desc> {
        self.descs.iter().collect()
    }

    fn collect(&self) -> Vec<MetricFamily> {
        let latest = self.gauges.refresh();
        let ids = self.gauges.ids.iter().copied();
        let vehicles: Vec<(u8, Latest)> = ids.zip(latest).collect();
        families(&vehicles, monotonic_ns())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::SampleHeader;

    const NOW: u64 = 100_000_000_000;

    fn header(age: Duration) -> SampleHeader {
        SampleHeader {
            seq: 1,
            stamp_ns: NOW - age.as_nanos() as u64,
            ..SampleHeader::default()
        }
    }

    fn value(fams: &[MetricFamily], name: &str, labels: &[(&str, &str)]) -> f64 {
        let fam = fams
            .iter()
            .find(|f| f.name() == name)
            .unwrap_or_else(|| panic!("no family {name}"));
        fam.get_metric()
            .iter()
            .find(|m| {
                labels.iter().all(|(k, v)| {
                    m.get_label()
                        .iter()
                        .any(|l| l.name() == *k && l.value() == *v)
                })
            })
            .unwrap_or_else(|| panic!("no series {name}{labels:?}"))
            .get_gauge()
            .get_value()
    }

    fn flying() -> Latest {
        Latest {
            state: Some(VehicleState {
                header: header(Duration::from_millis(20)),
                vehicle_id: 1,
                position_valid: 1,
                alt_rel_m: 12.5,
                vel_ned_mps: [3.0, 4.0, -1.0],
                ..VehicleState::default()
            }),
            status: Some(VehicleStatus {
                header: header(Duration::from_millis(500)),
                vehicle_id: 1,
                mode: FlightMode::Guided.to_wire(),
                armed: 1,
                link_up: 1,
                battery_remaining_pct: 76,
                battery_voltage_v: 15.9,
                ..VehicleStatus::default()
            }),
            authority: None,
        }
    }

    #[test]
    fn a_flying_vehicle_has_every_gauge() {
        let fams = families(&[(1, flying())], NOW);
        let v1 = [("vehicle", "1")];
        assert_eq!(value(&fams, "skymesh_vehicle_altitude_meters", &v1), 12.5);
        assert_eq!(
            value(&fams, "skymesh_vehicle_ground_speed_meters_per_second", &v1),
            5.0
        );
        assert_eq!(
            value(&fams, "skymesh_vehicle_battery_remaining_ratio", &v1),
            0.76
        );
        assert!((value(&fams, "skymesh_vehicle_battery_voltage_volts", &v1) - 15.9).abs() < 1e-5);
        assert_eq!(value(&fams, "skymesh_vehicle_armed", &v1), 1.0);
        assert_eq!(value(&fams, "skymesh_vehicle_link_up", &v1), 1.0);
        assert_eq!(
            value(
                &fams,
                "skymesh_vehicle_mode",
                &[("vehicle", "1"), ("mode", "guided")]
            ),
            1.0
        );
        assert_eq!(
            value(
                &fams,
                "skymesh_vehicle_mode",
                &[("vehicle", "1"), ("mode", "rtl")]
            ),
            0.0
        );
        assert!((value(&fams, "skymesh_vehicle_telemetry_age_seconds", &v1) - 0.02).abs() < 1e-9);
        assert!((value(&fams, "skymesh_vehicle_status_age_seconds", &v1) - 0.5).abs() < 1e-9);
        // One series per mode, and every family is a gauge.
        let modes = fams
            .iter()
            .find(|f| f.name() == "skymesh_vehicle_mode")
            .unwrap();
        assert_eq!(modes.get_metric().len(), FlightMode::ALL.len());
        assert!(fams.iter().all(|f| f.get_field_type() == MetricType::GAUGE));
        assert_eq!(fams.len(), FAMILIES.len());
    }

    #[test]
    fn before_any_sample_every_series_exists_with_unknown_values() {
        let fams = families(&[(1, Latest::default()), (7, Latest::default())], NOW);
        for id in ["1", "7"] {
            let v = [("vehicle", id)];
            for nan in [
                "skymesh_vehicle_altitude_meters",
                "skymesh_vehicle_ground_speed_meters_per_second",
                "skymesh_vehicle_battery_remaining_ratio",
                "skymesh_vehicle_battery_voltage_volts",
                "skymesh_vehicle_telemetry_age_seconds",
                "skymesh_vehicle_status_age_seconds",
            ] {
                assert!(value(&fams, nan, &v).is_nan(), "{nan}");
            }
            assert_eq!(value(&fams, "skymesh_vehicle_armed", &v), 0.0);
            assert_eq!(value(&fams, "skymesh_vehicle_link_up", &v), 0.0);
            assert_eq!(
                value(
                    &fams,
                    "skymesh_vehicle_mode",
                    &[("vehicle", id), ("mode", "unknown")]
                ),
                1.0
            );
        }
        assert!(families(&[], NOW).is_empty());
    }

    #[test]
    fn a_stale_status_or_a_lost_link_is_link_down_and_not_armed() {
        let mut stale = flying();
        stale.status.as_mut().unwrap().header = header(STATUS_STALE + Duration::from_millis(1));
        let fams = families(&[(1, stale)], NOW);
        assert_eq!(
            value(&fams, "skymesh_vehicle_link_up", &[("vehicle", "1")]),
            0.0
        );
        assert_eq!(
            value(&fams, "skymesh_vehicle_armed", &[("vehicle", "1")]),
            0.0
        );
        // The last known position stays, with its age telling how old it is.
        assert_eq!(
            value(
                &fams,
                "skymesh_vehicle_altitude_meters",
                &[("vehicle", "1")]
            ),
            12.5
        );

        let mut lost = flying();
        lost.status.as_mut().unwrap().link_up = 0;
        let fams = families(&[(1, lost)], NOW);
        assert_eq!(
            value(&fams, "skymesh_vehicle_link_up", &[("vehicle", "1")]),
            0.0
        );
        assert_eq!(
            value(&fams, "skymesh_vehicle_armed", &[("vehicle", "1")]),
            0.0
        );
    }

    /// Registered next to the mesh's collector (which declares no descriptions),
    /// and rendered in the text format with NaN for unknown values.
    #[test]
    fn the_collector_registers_beside_the_mesh_and_renders() {
        let mesh = Arc::new(crate::state::Mesh::new(&[("a".into(), false)], false));
        let registry = crate::metrics::registry(mesh).unwrap();
        let gauges = Arc::new(VehicleGauges::new(&[1]));
        registry
            .register(Box::new(Collect::new(gauges).unwrap()))
            .unwrap();
        let text = crate::metrics::render(&registry).unwrap();
        assert!(
            text.contains("skymesh_vehicle_link_up{vehicle=\"1\"} 0"),
            "{text}"
        );
        assert!(
            text.contains("skymesh_vehicle_altitude_meters{vehicle=\"1\"} NaN"),
            "{text}"
        );
        assert!(text.contains("# TYPE skymesh_vehicle_mode gauge"), "{text}");
        assert!(text.contains("skymesh_service_up{service=\"a\"}"), "{text}");
    }

    #[test]
    fn unknown_battery_and_position_are_nan() {
        let mut l = flying();
        l.status.as_mut().unwrap().battery_remaining_pct = -1;
        l.state.as_mut().unwrap().position_valid = 0;
        let fams = families(&[(1, l)], NOW);
        let v1 = [("vehicle", "1")];
        assert!(value(&fams, "skymesh_vehicle_battery_remaining_ratio", &v1).is_nan());
        assert!(value(&fams, "skymesh_vehicle_altitude_meters", &v1).is_nan());
        assert!(value(&fams, "skymesh_vehicle_ground_speed_meters_per_second", &v1).is_nan());
    }
}
