//! The engine driven through its public methods, with simulated time: no
//! processes, no bus, no clock.

mod entry;
mod event_steps;
mod exits;
mod follow;
mod geofence;
mod gopro;
mod idle;
mod multipoint;
mod pano;
mod persistence;
mod rewind;
mod shots;
mod sitescan;
mod unimplemented;
mod zipline;

use std::path::{Path, PathBuf};

use skymesh_ipc_types::shot_api::{Location, ShotEvent, ShotRequest, ShotRequestSample};
use skymesh_ipc_types::{
    AckResult, AppSession, ArbiterEvent, ArbiterEventKind, AuthorityState, Button, ButtonEvent,
    ButtonEventKind, Command, CommandAck, CommandKind, CommandSource, FixedStr, FlightMode,
    PayloadState, RefusalReason, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::Stats;

use super::{Engine, Outputs};
use crate::config::{RawConfig, Settings};
use crate::metrics::Metrics;
use crate::persist::Store;

pub const VEHICLE: u8 = 1;
pub const MS: u64 = 1_000_000;
/// Where the simulated vehicle hovers: SITL's field, 20 m up.
pub const LAT: f64 = -35.363261;
pub const LON: f64 = 149.165230;
pub const ALT: f32 = 20.0;

/// One metre of latitude, degrees.
pub const M_LAT: f64 = 1.0 / 111_320.0;

pub fn settings(state_file: &Path) -> Settings {
    let mut s = RawConfig::default()
        .validate_with_env(None, Some("test"))
        .unwrap();
    s.state_file = state_file.to_path_buf();
    s
}

/// How the simulated arbiter answers the engine's `GeofenceSet`s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FenceAnswer {
    /// `GeofenceUpdated` with the sample's request id, as soon as it is published.
    Take,
    /// `GeofenceInvalid` with the sample's request id.
    Refuse,
    /// Nothing (autopilot-link not running).
    Silent,
}

/// An engine with its own state file and a simulated clock.
pub struct Harness {
    /// The simulated arbiter's answer to every published `GeofenceSet`.
    pub fence_answer: FenceAnswer,
    /// Every `GeofenceSet` published, oldest first.
    pub fences: Vec<skymesh_ipc_types::GeofenceSet>,
    pub engine: Engine,
    pub now: u64,
    pub stats: Stats,
    pub state_file: PathBuf,
    pub status: VehicleStatus,
    pub state: VehicleState,
    /// The app session the simulated gateway republishes with every tick (like its
    /// 1 s republish), while `gateway_alive`.
    pub app_session: Option<u32>,
    pub gateway_alive: bool,
    _dir: Option<tempfile::TempDir>,
}

impl Harness {
    pub fn new() -> Harness {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("shot-engine.json");
        let mut h = Harness::on_file(&path);
        h._dir = Some(dir);
        h
    }

    /// An engine on an existing state file (the caller keeps the directory).
    pub fn on_file(path: &Path) -> Harness {
        let stats = Stats::new();
        let (store, _) = Store::open(path);
        let engine = Engine::new(settings(path), store, Metrics::new(&stats));
        Harness {
            fence_answer: FenceAnswer::Take,
            fences: Vec::new(),
            engine,
            now: 1_000 * MS,
            stats,
            state_file: path.to_path_buf(),
            status: VehicleStatus::default(),
            state: VehicleState::default(),
            app_session: None,
            gateway_alive: true,
            _dir: None,
        }
    }

    /// Armed, healthy, LOITER, link up, 80 % battery, hovering at 20 m; an app connected.
    pub fn ready() -> Harness {
        let mut h = Harness::new();
        h.vehicle_ok();
        h.connect_app(1);
        h.drain();
        h
    }

    pub fn vehicle_ok(&mut self) {
        self.status = VehicleStatus {
            vehicle_id: VEHICLE,
            mode: FlightMode::Loiter.to_wire(),
            armed: 1,
            ekf_healthy: 1,
            gps_fix: 3,
            link_up: 1,
            battery_remaining_pct: 80,
            home_valid: 1,
            ..VehicleStatus::default()
        };
        self.state = VehicleState {
            vehicle_id: VEHICLE,
            position_valid: 1,
            attitude_valid: 1,
            lat_deg: LAT,
            lon_deg: LON,
            alt_rel_m: ALT,
            heading_deg: 90.0,
            ..VehicleState::default()
        };
        self.push_status();
        self.push_state();
    }

    /// The status as autopilot-link publishes it: stamped now, describing a
    /// heartbeat `status.heartbeat_age_ms` old.
    pub fn push_status(&mut self) {
        let mut s = self.status;
        s.header.stamp_ns = self.now;
        self.engine.handle_status(&s, self.now);
    }

    pub fn push_state(&mut self) {
        let s = self.state;
        self.engine.handle_state(&s, self.now);
    }

    pub fn set_mode(&mut self, mode: FlightMode) -> Outputs {
        self.status.mode = mode.to_wire();
        self.push_status();
        self.drain()
    }

    /// Moves the simulated vehicle `north_m` metres north.
    pub fn move_north(&mut self, north_m: f64) {
        self.state.lat_deg += north_m * M_LAT;
        self.push_state();
    }

    pub fn payload(&mut self, p: PayloadState) -> Outputs {
        self.engine.handle_payload(
            &PayloadState {
                vehicle_id: VEHICLE,
                ..p
            },
            self.now,
        );
        self.drain()
    }

    pub fn connect_app(&mut self, session: u32) -> Outputs {
        self.session(session, true)
    }

    pub fn session(&mut self, session: u32, connected: bool) -> Outputs {
        self.app_session = connected.then_some(session);
        self.engine.handle_app_session(
            &AppSession {
                session,
                connected: connected.into(),
                peer: FixedStr::new("10.1.1.10:40000"),
                ..AppSession::default()
            },
            self.now,
        );
        self.drain()
    }

    /// A request from app session 1 (an options event stands for the request
    /// with the same options).
    pub fn app(&mut self, msg: impl AsRequest) -> Outputs {
        let m = ShotRequestSample::new(1, &msg.request());
        self.engine.handle_app(&m, self.now);
        self.drain()
    }

    /// A follow-stream position (UDP) `north_m` north of the vehicle's start.
    pub fn fix(&mut self, north_m: f64) {
        let mut m = ShotRequestSample::new(
            0,
            &ShotRequest::Location(Location {
                lat_deg: LAT + north_m * M_LAT,
                lon_deg: LON,
                alt_m: 0.0,
            }),
        );
        m.session = 1;
        m.flags = skymesh_ipc_types::shot_api::request_flags::FOLLOW_STREAM;
        self.engine.handle_app(&m, self.now);
    }

    pub fn button(&mut self, button: Button) -> Outputs {
        self.engine.handle_button(
            &ButtonEvent::new(VEHICLE, button, ButtonEventKind::Press),
            self.now,
        );
        self.drain()
    }

    pub fn drain(&mut self) -> Outputs {
        let out = self.engine.drain(self.now);
        self.arbiter(out)
    }

    /// The simulated arbiter decides on a published `GeofenceSet` (`fence_answer`);
    /// what the engine answers is added to `out`.
    fn arbiter(&mut self, mut out: Outputs) -> Outputs {
        let Some(set) = out.geofence else {
            return out;
        };
        self.fences.push(set);
        let kind = match self.fence_answer {
            FenceAnswer::Take => ArbiterEventKind::GeofenceUpdated,
            FenceAnswer::Refuse => ArbiterEventKind::GeofenceInvalid,
            FenceAnswer::Silent => return out,
        };
        let ev = ArbiterEvent {
            vehicle_id: set.vehicle_id,
            kind: kind.to_wire(),
            source: set.source,
            request_id: set.request_id,
            detail: FixedStr::new("polygon 0 crosses itself"),
            ..ArbiterEvent::default()
        };
        self.engine.handle_arbiter_event(&ev, self.now);
        let more = self.engine.drain(self.now);
        out.commands.extend(more.commands);
        out.to_app.extend(more.to_app);
        out.status = more.status.or(out.status);
        out
    }

    /// One loop tick 40 ms later (the vehicle state is refreshed first).
    pub fn tick(&mut self) -> Outputs {
        self.now += 40 * MS;
        self.push_state();
        if let (true, Some(session)) = (self.gateway_alive, self.app_session) {
            self.engine.handle_app_session(
                &AppSession {
                    session,
                    connected: 1,
                    ..AppSession::default()
                },
                self.now,
            );
        }
        let out = self.engine.tick(self.now);
        self.arbiter(out)
    }

    /// Ticks for `ms` of simulated time, collecting everything.
    pub fn run(&mut self, ms: u64) -> Outputs {
        let mut all = Outputs::default();
        for _ in 0..ms / 40 {
            let o = self.tick();
            all.commands.extend(o.commands);
            all.to_app.extend(o.to_app);
            all.status = o.status.or(all.status);
        }
        all
    }

    pub fn authority(&mut self, holder: Option<CommandSource>) -> Outputs {
        let st = AuthorityState {
            vehicle_id: VEHICLE,
            flight_holder: holder.map_or(skymesh_ipc_types::NO_HOLDER, CommandSource::to_wire),
            ..AuthorityState::default()
        };
        self.engine.handle_authority(&st, self.now);
        self.drain()
    }

    /// The ack autopilot-link would publish for `cmd`.
    pub fn ack(
        &mut self,
        cmd: &VehicleCommand,
        result: AckResult,
        reason: RefusalReason,
    ) -> Outputs {
        let ack = CommandAck {
            vehicle_id: VEHICLE,
            source: CommandSource::ShotEngine.to_wire(),
            kind: cmd.kind,
            result: result.to_wire(),
            command_id: cmd.command_id,
            reason: reason.to_wire(),
            detail: FixedStr::new("test"),
            ..CommandAck::default()
        };
        self.engine.handle_ack(&ack, self.now);
        self.drain()
    }

    pub fn counter(&self, name: &str, labels: &[(&str, &str)]) -> u64 {
        self.stats.counter(name, labels).get()
    }

    /// Enters orbit and locks an ROI 30 m north: flying.
    pub fn orbiting(&mut self) -> Outputs {
        self.app(ShotRequest::StartShot(
            skymesh_ipc_types::shot_api::shots::ORBIT,
        ));
        let out = self.app(ShotRequest::Location(loc(30.0)));
        self.set_mode(FlightMode::Guided);
        out
    }
}

/// A location `north_m` north of the start, on the ground.
pub fn loc(north_m: f64) -> Location {
    Location {
        lat_deg: LAT + north_m * M_LAT,
        lon_deg: LON,
        alt_m: 0.0,
    }
}

/// The typed commands of `out`.
pub fn cmds(out: &Outputs) -> Vec<Command> {
    out.commands.iter().map(|c| c.command().unwrap()).collect()
}

/// The kinds of the commands of `out`, without the velocity setpoints.
pub fn kinds(out: &Outputs) -> Vec<CommandKind> {
    out.commands
        .iter()
        .map(|c| c.kind().unwrap())
        .filter(|k| *k != CommandKind::VelocityNed)
        .collect()
}

pub fn find(out: &Outputs, kind: CommandKind) -> Option<VehicleCommand> {
    out.commands
        .iter()
        .copied()
        .find(|c| c.kind == kind.to_wire())
}

/// Every command of `out` is from the shot engine for our vehicle.
pub fn all_ours(out: &Outputs) -> bool {
    out.commands
        .iter()
        .all(|c| c.vehicle_id == VEHICLE && c.source == CommandSource::ShotEngine.to_wire())
}

/// What [`Harness::app`] sends: a request, or an options event that the app sends
/// back as the same options.
pub trait AsRequest {
    fn request(self) -> ShotRequest;
}

impl AsRequest for ShotRequest {
    fn request(self) -> ShotRequest {
        self
    }
}

impl AsRequest for ShotEvent {
    fn request(self) -> ShotRequest {
        use ShotEvent as E;
        use ShotRequest as R;
        match self {
            E::PanoOptions {
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov,
            } => R::PanoOptions {
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov,
            },
            E::ZiplineOptions {
                cruise_speed,
                is_3d,
                cam_pointing,
            } => R::ZiplineOptions {
                cruise_speed,
                is_3d,
                cam_pointing,
            },
            E::RewindOptions {
                enabled,
                hover,
                rewind_distance,
            } => R::RewindOptions {
                enabled,
                hover,
                rewind_distance,
            },
            E::ShotOptions { cruise_speed } => R::ShotOptions { cruise_speed },
            other => panic!("{} is no request", other.name()),
        }
    }
}
