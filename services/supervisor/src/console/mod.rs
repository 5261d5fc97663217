//! The web console served by the supervisor at `/` on its HTTP address: a page
//! (HTML, CSS and JavaScript built into the binary: no build step, nothing fetched
//! from elsewhere) that polls two JSON documents, and two actions behind a token.
//!
//! - `GET /`, `/console.css`, `/console.js`: the page ([`assets`]).
//! - `GET /api/mesh`: the service table ([`api::service_row`]).
//! - `GET /api/vehicles`: each configured vehicle ([`api::vehicle`]).
//! - `POST /api/services/{name}/restart`: restart a service (crate::supervise's
//!   [`RestartRequests`]); 202 once asked.
//! - `POST /api/vehicles/{id}/emergency-stop` and `…/release-emergency`: a
//!   `VehicleCommand` from source `operator` through the vehicle's arbiter; the
//!   answer carries the arbiter's `CommandAck`.
//!
//! Actions need `Authorization: Bearer <token>` with the token of
//! `supervisor.console_token(_file)` ([`settings`]); without a configured token
//! they do not exist (the page shows none, the endpoints answer 403). Unless
//! `supervisor.console_remote`, only loopback peers are answered. docs/console.md
//! is the operator's description.

pub mod api;
pub mod assets;
pub mod feed;
pub mod settings;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use bytes::Bytes;
use http_body_util::Full;
use hyper::header::{HeaderValue, ALLOW, AUTHORIZATION, CACHE_CONTROL, CONTENT_TYPE};
use hyper::{Method, Request, Response, StatusCode};
use serde_json::{json, Value};
use skymesh_ipc_types::{topics, AckResult, Command, CommandSource, VehicleCommand};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, IpcError, Publisher};

pub use settings::{ConsoleSettings, Token};

use crate::state::{Mesh, Phase};
use crate::supervise::RestartRequests;
use crate::vehicles::VehicleGauges;

/// How long an action waits for the arbiter's answer before saying it sent the
/// command without one: longer than autopilot-link's default
/// `stop_confirm_timeout_s` (5 s), the longest an emergency stop's answer takes.
pub const ACK_WAIT: Duration = Duration::from_secs(8);
/// How often it looks for that answer meanwhile.
const ACK_POLL: Duration = Duration::from_millis(50);

/// A response of the supervisor's HTTP server.
pub type Reply = Response<Full<Bytes>>;

/// Whether a path is the console's (the HTTP server routes it here).
pub fn is_console_path(path: &str) -> bool {
    assets::find(path).is_some() || path.starts_with("/api/")
}

/// The console's state: what it reads and the handles its actions use.
pub struct Console {
    mesh: Arc<Mesh>,
    vehicles: Arc<VehicleGauges>,
    /// `None` with `--monitor-only` (systemd restarts services there, not us).
    restarts: Option<Arc<RestartRequests>>,
    settings: ConsoleSettings,
    cpu: Mutex<api::CpuMeter>,
    /// One command publisher per configured vehicle, once the bus is open and only
    /// when actions exist.
    commands: Mutex<Option<Vec<Publisher<VehicleCommand>>>>,
    next_command_id: AtomicU32,
}

impl std::fmt::Debug for Console {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Console")
            .field("actions", &self.settings.actions())
            .field("remote", &self.settings.remote)
            .finish()
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A JSON response.
fn json_reply(status: StatusCode, v: &Value) -> Reply {
    let mut body = serde_json::to_vec(v).unwrap_or_default();
    body.push(b'\n');
    let mut r = Response::new(Full::new(Bytes::from(body)));
    *r.status_mut() = status;
    r.headers_mut()
        .insert(CONTENT_TYPE, HeaderValue::from_static("application/json"));
    r.headers_mut()
        .insert(CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// A refusal: `{"error": why}` with `status`.
fn refuse(status: StatusCode, why: impl Into<String>) -> Reply {
    json_reply(status, &json!({ "error": why.into() }))
}

fn method_not_allowed(allow: &'static str) -> Reply {
    let mut r = refuse(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("method not allowed here (use {allow})"),
    );
    r.headers_mut()
        .insert(ALLOW, HeaderValue::from_static(allow));
    r
}

/// The action a `POST /api/…` path names.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Action<'a> {
    Restart(&'a str),
    Vehicle(&'a str, VehicleAction),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum VehicleAction {
    EmergencyStop,
    ReleaseEmergency,
}

impl VehicleAction {
    fn command(self) -> Command {
        match self {
            VehicleAction::EmergencyStop => Command::EmergencyStop,
            VehicleAction::ReleaseEmergency => Command::ReleaseEmergency,
        }
    }
}

fn parse_action(path: &str) -> Option<Action<'_>> {
    let rest = path.strip_prefix("/api/")?;
    let parts: Vec<&str> = rest.split('/').collect();
    match parts.as_slice() {
        ["services", name, "restart"] => Some(Action::Restart(name)),
        ["vehicles", id, "emergency-stop"] => {
            Some(Action::Vehicle(id, VehicleAction::EmergencyStop))
        }
        ["vehicles", id, "release-emergency"] => {
            Some(Action::Vehicle(id, VehicleAction::ReleaseEmergency))
        }
        _ => None,
    }
}

fn is_loopback(peer: SocketAddr) -> bool {
    peer.ip().to_canonical().is_loopback()
}

impl Console {
    pub fn new(
        mesh: Arc<Mesh>,
        vehicles: Arc<VehicleGauges>,
        restarts: Option<Arc<RestartRequests>>,
        settings: ConsoleSettings,
    ) -> Self {
        Console {
            mesh,
            vehicles,
            restarts,
            settings,
            cpu: Mutex::new(api::CpuMeter::default()),
            commands: Mutex::new(None),
            // Acks are matched by (source, id) and the operator source is shared
            // with other tools: start somewhere unlikely to meet theirs.
            next_command_id: AtomicU32::new(0x4000_0000 | fastrand::u32(..0x3fff_0000)),
        }
    }

    /// Opens the command publishers on `bus` when actions exist.
    pub fn attach(&self, bus: &Bus) -> Result<(), IpcError> {
        if !self.settings.actions() {
            return Ok(());
        }
        let publishers = self
            .vehicles
            .ids()
            .iter()
            .map(|&id| bus.publisher::<VehicleCommand>(&topics::vehicle_command(id)))
            .collect::<Result<Vec<_>, _>>()?;
        *lock(&self.commands) = Some(publishers);
        Ok(())
    }

    /// Drops the command publishers (before the bus's node goes).
    pub fn detach(&self) {
        *lock(&self.commands) = None;
    }

    /// Answers one request for a console path from `peer`.
    pub async fn handle<B>(&self, req: &Request<B>, peer: SocketAddr) -> Reply {
        if !self.settings.remote && !is_loopback(peer) {
            return refuse(
                StatusCode::FORBIDDEN,
                "the console answers loopback peers only (supervisor.console_remote)",
            );
        }
        let path = req.uri().path();
        if let Some(asset) = assets::find(path) {
            return match *req.method() {
                Method::GET | Method::HEAD => assets::reply(asset),
                _ => method_not_allowed("GET, HEAD"),
            };
        }
        match path {
            "/api/mesh" | "/api/vehicles" => {
                if !matches!(*req.method(), Method::GET | Method::HEAD) {
                    return method_not_allowed("GET, HEAD");
                }
                let doc = if path == "/api/mesh" {
                    self.mesh_doc()
                } else {
                    self.vehicles_doc()
                };
                return json_reply(StatusCode::OK, &doc);
            }
            _ => {}
        }
        let Some(action) = parse_action(path) else {
            return refuse(
                StatusCode::NOT_FOUND,
                "no such console endpoint (see docs/console.md)",
            );
        };
        if *req.method() != Method::POST {
            return method_not_allowed("POST");
        }
        if let Err(why) = self.authorize(req) {
            return refuse(StatusCode::FORBIDDEN, why);
        }
        match action {
            Action::Restart(name) => self.restart(name),
            Action::Vehicle(id, what) => self.vehicle_action(id, what).await,
        }
    }

    /// Checks the request's bearer token; `Err` says why it is refused.
    fn authorize<B>(&self, req: &Request<B>) -> Result<(), &'static str> {
        let Some(token) = &self.settings.token else {
            return Err("the console's actions are off (no supervisor.console_token)");
        };
        let offered = req
            .headers()
            .get(AUTHORIZATION)
            .and_then(|v| v.as_bytes().strip_prefix(b"Bearer "));
        match offered {
            Some(t) if token.matches(t) => Ok(()),
            Some(_) => Err("wrong token"),
            None => Err("an action needs `Authorization: Bearer <console token>`"),
        }
    }

    fn restart(&self, name: &str) -> Reply {
        let Some(idx) = self.mesh.index_of(name) else {
            return refuse(StatusCode::NOT_FOUND, "no such service");
        };
        let Some(restarts) = &self.restarts else {
            return refuse(
                StatusCode::CONFLICT,
                "monitor-only: systemd runs the services (systemctl restart the unit)",
            );
        };
        let (phase, pid) = self.mesh.with(idx, |e| (e.phase, e.pid));
        let busy = phase == Phase::Stopping || (phase == Phase::Starting && pid.is_none());
        if busy {
            return refuse(
                StatusCode::CONFLICT,
                format!("the service is {phase}; try again once it runs"),
            );
        }
        restarts.request(idx);
        tracing::warn!(service = %name, state = %phase, pid, "restart asked for in the web console");
        json_reply(
            StatusCode::ACCEPTED,
            &json!({ "service": name, "restart": "requested", "state": phase.as_str() }),
        )
    }

    async fn vehicle_action(&self, id: &str, what: VehicleAction) -> Reply {
        let Some(idx) = id
            .parse::<u8>()
            .ok()
            .and_then(|id| self.vehicles.ids().iter().position(|v| *v == id))
        else {
            return refuse(
                StatusCode::NOT_FOUND,
                "no such vehicle (supervisor.vehicles)",
            );
        };
        let vehicle = self.vehicles.ids()[idx];
        let command = what.command();
        let command_id = self.next_command_id.fetch_add(1, Ordering::Relaxed);
        let sent = {
            let mut commands = lock(&self.commands);
            match commands.as_mut().and_then(|c| c.get_mut(idx)) {
                None => Err("the supervisor has not joined the bus yet".to_string()),
                Some(p) => {
                    VehicleCommand::new(vehicle, CommandSource::Operator, command_id, &command)
                        .map_err(|e| e.to_string())
                        .and_then(|c| p.publish(c).map_err(|e| e.to_string()))
                }
            }
        };
        if let Err(e) = sent {
            tracing::error!(vehicle, error = %e, "sending the console's command failed");
            return refuse(StatusCode::SERVICE_UNAVAILABLE, e);
        }
        tracing::warn!(vehicle, command = ?command, command_id, "command sent from the web console (source operator)");
        let deadline = Instant::now() + ACK_WAIT;
        loop {
            if let Some(ack) = self
                .vehicles
                .find_ack(idx, CommandSource::Operator, command_id)
            {
                let refused = ack.result() == Some(AckResult::Refused);
                return json_reply(
                    if refused {
                        StatusCode::CONFLICT
                    } else {
                        StatusCode::OK
                    },
                    &json!({
                        "vehicle": vehicle,
                        "command": command.kind().as_str(),
                        "command_id": command_id,
                        "result": ack.result().map_or("unknown", AckResult::as_str),
                        "reason": ack.reason().map_or("unknown", |r| r.as_str()),
                        "detail": ack.detail.as_str(),
                    }),
                );
            }
            if Instant::now() >= deadline {
                return json_reply(
                    StatusCode::ACCEPTED,
                    &json!({
                        "vehicle": vehicle,
                        "command": command.kind().as_str(),
                        "command_id": command_id,
                        "result": "sent",
                        "detail": "no answer from the vehicle's arbiter yet (is autopilot-link running?)",
                    }),
                );
            }
            tokio::time::sleep(ACK_POLL).await;
        }
    }

    /// `/api/mesh`.
    pub fn mesh_doc(&self) -> Value {
        let now_ns = monotonic_ns();
        let now = Instant::now();
        let entries = self.mesh.with_all(|es| es.to_vec());
        let mut cpu = lock(&self.cpu);
        let services: Vec<Value> = entries
            .iter()
            .map(|e| {
                let usage = e.pid.and_then(crate::procfs::usage);
                let pct = e
                    .pid
                    .zip(usage)
                    .and_then(|(pid, u)| cpu.percent(&e.name, pid, u.cpu_seconds, now));
                api::service_row(e, usage, pct, now_ns)
            })
            .collect();
        json!({
            "version": crate::VERSION,
            "git": crate::GIT,
            "monitor_only": self.mesh.monitor_only,
            "actions": self.settings.actions(),
            "restart_action": self.settings.actions() && self.restarts.is_some(),
            "supervisor_uptime_s": (self.mesh.started.elapsed().as_secs_f64() * 10.0).round() / 10.0,
            "services": services,
        })
    }

    /// `/api/vehicles`.
    pub fn vehicles_doc(&self) -> Value {
        let now_ns = monotonic_ns();
        let vehicles: Vec<Value> = self
            .vehicles
            .snapshot()
            .iter()
            .map(|(id, l, log)| api::vehicle(*id, l, log, now_ns))
            .collect();
        json!({
            "actions": self.settings.actions(),
            "vehicles": vehicles,
        })
    }
}

#[cfg(test)]
mod tests;
