//! A kinematic stand-in for N vehicles behind their autopilot links, for the unit
//! tests and the benchmark: it answers `VehicleCommand`s with `CommandAck`s roughly
//! as ArduCopter behind the arbiter would, moves in straight lines at a capped
//! speed, and publishes `VehicleState` / `VehicleStatus`. Not a flight model (the
//! real one is vehicle-sim).
//!
//! Its arbiter keeps the emergency stop's engagers as the real one does: a stop is
//! engaged under its sender's source, [`Command::ReleaseEmergency`] withdraws only
//! the sender's, [`Command::ClearEmergency`] from operator or safety ends every one,
//! and releasing flight authority never ends it. Geofences are answered with a
//! `GeofenceUpdated` / `GeofenceInvalid` event carrying the sample's `request_id`.
//!
//! Flight authority as the arbiter keeps it: a flight command (or a grab) that
//! passes takes it when free, pre-empts a lower source, refreshes the holder's; a
//! lower source is refused `NoAuthority`. The holder loses it after
//! [`FakeVehicle::authority_timeout_ns`] without a flight command (the vehicle's
//! clock is the sum of its [`FakeVehicle::step`] times), and a holder that loses it
//! (timeout or pre-emption) while its `GoTo` / `Takeoff` is the position target is
//! braked: counted in [`FakeVehicle::target_brakes`], a `StaleBrake` event. Any
//! other motion command of the holder ends the target, as in the arbiter.

use skymesh_ipc_types::{
    AckResult, ArbiterEvent, ArbiterEventKind, AuthorityDomain, Command, CommandAck, CommandKind,
    CommandSource, FixedStr, FlightMode, GeofenceSet, RefusalReason, VehicleCommand, VehicleState,
    VehicleStatus,
};

use crate::core::Swarm;
use crate::site::{heading_of_yaw, SiteFrame};

/// One simulated vehicle; positions in the site frame.
#[derive(Debug, Clone)]
pub struct FakeVehicle {
    pub vehicle_id: u8,
    pub site: SiteFrame,
    /// Home, site frame (z = ground height above the site origin).
    pub home: [f64; 3],
    pub pos: [f64; 3],
    pub vel: [f64; 3],
    pub armed: bool,
    pub mode: FlightMode,
    /// Compass heading, degrees.
    pub heading: f32,
    pub target: Option<[f64; 3]>,
    pub speed: f64,
    /// Kinds answered `Denied` (test hook).
    pub refuse: Vec<CommandKind>,
    /// Kinds never answered (test hook).
    pub ignore: Vec<CommandKind>,
    /// Every command received, in order.
    pub received: Vec<Command>,
    pub link_up: bool,
    /// The sources whose emergency stop is in force (bit `1 << source`).
    pub emergency_sources: u8,
    /// Geofences answered `GeofenceInvalid` (test hook).
    pub refuse_fences: bool,
    /// Geofences never answered (test hook).
    pub ignore_fences: bool,
    /// Arbiter events not yet delivered.
    pub events: Vec<ArbiterEvent>,
    /// The vehicle's clock: the sum of its steps, ns.
    pub clock_ns: u64,
    /// The arbiter's flight authority holder.
    pub holder: Option<CommandSource>,
    /// When the holder was last heard from (a flight command or grab), `clock_ns`.
    pub heard_ns: u64,
    /// The arbiter's `authority_timeout_s` (default 5 s), ns.
    pub authority_timeout_ns: u64,
    /// The source whose `GoTo` / `Takeoff` the vehicle flies.
    pub position_target: Option<CommandSource>,
    /// Position targets braked because their source lost flight authority.
    pub target_brakes: u32,
}

/// autopilot-link's default `authority_timeout_s`, ns.
pub const AUTHORITY_TIMEOUT_NS: u64 = 5_000_000_000;

/// Climb rate, m/s.
const CLIMB_MPS: f64 = 2.5;
/// Descent rate in LAND, m/s.
const LAND_MPS: f64 = 1.0;

impl FakeVehicle {
    /// Disarmed on the ground at site point `home` (x, y; ground at z).
    pub fn new(vehicle_id: u8, site: SiteFrame, home: [f64; 3]) -> Self {
        FakeVehicle {
            vehicle_id,
            site,
            home,
            pos: home,
            vel: [0.0; 3],
            armed: false,
            mode: FlightMode::Stabilize,
            heading: 0.0,
            target: None,
            speed: 5.0,
            refuse: Vec::new(),
            ignore: Vec::new(),
            received: Vec::new(),
            link_up: true,
            emergency_sources: 0,
            refuse_fences: false,
            ignore_fences: false,
            events: Vec::new(),
            clock_ns: 0,
            holder: None,
            heard_ns: 0,
            authority_timeout_ns: AUTHORITY_TIMEOUT_NS,
            position_target: None,
            target_brakes: 0,
        }
    }

    /// `source` lost flight authority (timeout or pre-emption): its position target
    /// is braked, as the arbiter's `TargetBrake` does (a hover, in GUIDED).
    fn lost_authority(&mut self, source: CommandSource, why: &str) {
        if self.position_target != Some(source) {
            return;
        }
        self.position_target = None;
        self.target_brakes += 1;
        if self.mode == FlightMode::Guided {
            self.target = Some(self.pos);
        }
        let detail = format!("position target orphaned ({why}): braked to a hover");
        self.event(ArbiterEventKind::StaleBrake, source.to_wire(), 0, &detail);
    }

    /// The arbiter's authority step for a command of `source` that passed the other
    /// checks: `Err` when a higher source holds flight authority.
    fn authority(
        &mut self,
        source: CommandSource,
        kind: CommandKind,
    ) -> Result<(), (RefusalReason, &'static str)> {
        if kind.authority() != Some(AuthorityDomain::Flight) {
            return Ok(());
        }
        if kind == CommandKind::ReleaseFlightAuthority {
            if self.holder == Some(source) && !self.emergency() {
                self.holder = None;
            }
            return Ok(());
        }
        match self.holder {
            Some(h) if h == source => {}
            Some(h) if h.priority() >= source.priority() => {
                return Err((
                    RefusalReason::NoAuthority,
                    "flight authority held by another source",
                ))
            }
            Some(h) => {
                self.holder = Some(source);
                self.lost_authority(h, "pre-empted");
            }
            None => self.holder = Some(source),
        }
        self.heard_ns = self.clock_ns;
        Ok(())
    }

    /// The arbiter's position target after an executed command of `source`.
    fn track_target(&mut self, source: CommandSource, kind: CommandKind) {
        match kind {
            CommandKind::GoTo | CommandKind::Takeoff => self.position_target = Some(source),
            CommandKind::EmergencyStop => self.position_target = None,
            CommandKind::VelocityNed
            | CommandKind::SetYaw
            | CommandKind::SetRoi
            | CommandKind::ClearRoi
            | CommandKind::SetHome => {}
            k if k.authority() == Some(AuthorityDomain::Flight) && !k.is_authority_request() => {
                self.position_target = None
            }
            _ => {}
        }
    }

    pub fn alt_rel(&self) -> f64 {
        self.pos[2] - self.home[2]
    }

    pub fn in_air(&self) -> bool {
        self.armed && self.alt_rel() > 0.2
    }

    /// Whether any emergency stop is in force.
    pub fn emergency(&self) -> bool {
        self.emergency_sources != 0
    }

    /// Whether `source`'s emergency stop is in force.
    pub fn emergency_by(&self, source: CommandSource) -> bool {
        self.emergency_sources & (1 << source.to_wire()) != 0
    }

    fn event(&mut self, kind: ArbiterEventKind, source: u8, request_id: u32, detail: &str) {
        self.events.push(ArbiterEvent {
            vehicle_id: self.vehicle_id,
            kind: kind.to_wire(),
            source,
            request_id,
            detail: FixedStr::new(detail),
            ..ArbiterEvent::default()
        });
    }

    /// The arbiter's answer to a geofence sample, queued on [`FakeVehicle::events`]
    /// (nothing with `ignore_fences`).
    pub fn handle_geofence(&mut self, g: &GeofenceSet) {
        if self.ignore_fences {
            return;
        }
        let (kind, detail) = if self.refuse_fences {
            (ArbiterEventKind::GeofenceInvalid, "test refusal")
        } else if g.vehicle_id != self.vehicle_id || g.polygons().is_err() {
            (ArbiterEventKind::GeofenceInvalid, "invalid fence")
        } else {
            (ArbiterEventKind::GeofenceUpdated, "fence set")
        };
        self.event(kind, g.source, g.request_id, detail);
    }

    /// Executes a command; `None` when it is ignored (no acknowledgement).
    pub fn handle(&mut self, c: &VehicleCommand) -> Option<CommandAck> {
        let cmd = c.command().ok()?;
        self.received.push(cmd);
        let kind = cmd.kind();
        if self.ignore.contains(&kind) {
            return None;
        }
        let source = CommandSource::try_from(c.source).ok();
        let bit = source.map_or(0, |s| 1u8 << s.to_wire());
        let clearer = [CommandSource::Operator, CommandSource::Safety]
            .iter()
            .any(|s| s.to_wire() == c.source);
        let stop_kinds = [
            CommandKind::EmergencyStop,
            CommandKind::ReleaseEmergency,
            CommandKind::ClearEmergency,
        ];
        let mut result = Ok(());
        if self.refuse.contains(&kind) {
            result = Err((RefusalReason::Denied, "test refusal"));
        } else if self.emergency() && !stop_kinds.contains(&kind) {
            result = Err((RefusalReason::Emergency, "emergency stop"));
        } else if let Some(Err(e)) = source.map(|s| self.authority(s, kind)) {
            result = Err(e);
        } else {
            match cmd {
                Command::SetMode(m) => self.mode = m,
                Command::Arm { .. } => self.armed = true,
                Command::Disarm { .. } => {
                    if self.in_air() {
                        result = Err((RefusalReason::Denied, "flying"));
                    } else {
                        self.armed = false;
                    }
                }
                Command::Takeoff { alt_rel_m } => {
                    if self.mode != FlightMode::Guided || !self.armed {
                        result = Err((RefusalReason::Denied, "not armed in GUIDED"));
                    } else {
                        self.target = Some([
                            self.pos[0],
                            self.pos[1],
                            self.home[2] + f64::from(alt_rel_m),
                        ]);
                    }
                }
                Command::GoTo {
                    lat_deg,
                    lon_deg,
                    alt_rel_m,
                    yaw_deg,
                    speed_mps,
                } => {
                    let [x, y] = self.site.to_site_xy(lat_deg, lon_deg);
                    if self.mode == FlightMode::Guided && self.in_air() {
                        self.target = Some([x, y, self.home[2] + f64::from(alt_rel_m)]);
                        if let Some(h) = yaw_deg {
                            self.heading = h;
                        }
                        if let Some(s) = speed_mps {
                            self.speed = f64::from(s).max(0.1);
                        }
                    }
                }
                Command::Land => self.mode = FlightMode::Land,
                Command::Brake => self.target = Some(self.pos),
                Command::EmergencyStop => {
                    self.emergency_sources |= bit;
                    self.holder = Some(CommandSource::Safety);
                    self.target = Some(self.pos);
                    self.event(ArbiterEventKind::EmergencyStop, c.source, 0, "engaged");
                }
                Command::ReleaseEmergency => {
                    if self.emergency_sources & bit == 0 {
                        result = Err((RefusalReason::Denied, "no emergency stop of its own"));
                    } else {
                        self.emergency_sources &= !bit;
                        self.event(ArbiterEventKind::EmergencyReleased, c.source, 0, "released");
                        if self.emergency_sources == 0 {
                            self.holder = None;
                            self.event(ArbiterEventKind::EmergencyCleared, c.source, 0, "ended");
                        }
                    }
                }
                Command::ClearEmergency if !clearer => {
                    result = Err((RefusalReason::Denied, "only operator or safety clear"))
                }
                Command::ClearEmergency if self.emergency_sources != 0 => {
                    self.emergency_sources = 0;
                    self.holder = None;
                    self.event(ArbiterEventKind::EmergencyCleared, c.source, 0, "cleared");
                }
                Command::SetYaw {
                    yaw_deg, relative, ..
                } => {
                    self.heading = if relative {
                        (self.heading + yaw_deg).rem_euclid(360.0)
                    } else {
                        yaw_deg
                    }
                }
                Command::SetHome {
                    lat_deg, lon_deg, ..
                } => {
                    let [x, y] = self.site.to_site_xy(lat_deg, lon_deg);
                    self.home[0] = x;
                    self.home[1] = y;
                }
                _ => {}
            }
        }
        if let (Ok(()), Some(s)) = (result, source) {
            self.track_target(s, kind);
        }
        let (res, reason, detail) = match result {
            Ok(()) => (AckResult::Accepted, RefusalReason::None, ""),
            Err((r, d)) => (AckResult::Refused, r, d),
        };
        Some(CommandAck {
            vehicle_id: self.vehicle_id,
            source: c.source,
            kind: c.kind,
            result: res.to_wire(),
            command_id: c.command_id,
            reason: reason.to_wire(),
            mav_result: CommandAck::NO_MAV_RESULT,
            detail: FixedStr::new(detail),
            ..CommandAck::default()
        })
    }

    /// Moves for `dt` seconds.
    pub fn step(&mut self, dt: f64) {
        self.clock_ns += (dt.max(0.0) * 1e9) as u64;
        if let Some(h) = self.holder {
            let quiet = self.clock_ns.saturating_sub(self.heard_ns) >= self.authority_timeout_ns;
            if quiet && !self.emergency() {
                self.holder = None;
                self.lost_authority(h, "authority timeout");
            }
        }
        let before = self.pos;
        if !self.armed {
            self.target = None;
        } else if self.mode == FlightMode::Land {
            self.target = None;
            self.pos[2] = (self.pos[2] - LAND_MPS * dt).max(self.home[2]);
            if self.pos[2] <= self.home[2] {
                self.armed = false;
            }
        } else if let Some(t) = self.target {
            let d = [t[0] - self.pos[0], t[1] - self.pos[1]];
            let h = (d[0] * d[0] + d[1] * d[1]).sqrt();
            let step = self.speed * dt;
            if h <= step {
                self.pos[0] = t[0];
                self.pos[1] = t[1];
            } else {
                self.pos[0] += d[0] / h * step;
                self.pos[1] += d[1] / h * step;
            }
            let dz = t[2] - self.pos[2];
            self.pos[2] += dz.clamp(-CLIMB_MPS * dt, CLIMB_MPS * dt);
        }
        self.pos[2] = self.pos[2].max(self.home[2]);
        if dt > 0.0 {
            self.vel = [0, 1, 2].map(|i| (self.pos[i] - before[i]) / dt);
        }
    }

    pub fn state(&self, now_ns: u64) -> VehicleState {
        let (lat, lon) = self.site.to_geodetic(self.pos[0], self.pos[1]);
        let h = self.heading.to_radians();
        VehicleState {
            vehicle_id: self.vehicle_id,
            position_valid: 1,
            attitude_valid: 1,
            lat_deg: lat,
            lon_deg: lon,
            alt_msl_m: self.site.msl_of_z(self.pos[2]) as f32,
            alt_rel_m: self.alt_rel() as f32,
            vel_ned_mps: [self.vel[1] as f32, self.vel[0] as f32, -self.vel[2] as f32],
            heading_deg: self.heading,
            attitude_q: [(h / 2.0).cos(), 0.0, 0.0, (h / 2.0).sin()],
            yaw_rad: h,
            position_stamp_ns: now_ns,
            ..VehicleState::default()
        }
    }

    pub fn status(&self) -> VehicleStatus {
        let (lat, lon) = self.site.to_geodetic(self.home[0], self.home[1]);
        VehicleStatus {
            vehicle_id: self.vehicle_id,
            mode: self.mode.to_wire(),
            armed: u8::from(self.armed),
            link_up: u8::from(self.link_up),
            ekf_healthy: 1,
            home_valid: 1,
            home_lat_deg: lat,
            home_lon_deg: lon,
            home_alt_msl_m: self.site.msl_of_z(self.home[2]) as f32,
            ..VehicleStatus::default()
        }
    }
}

/// The vehicles of every drone of a [`Swarm`], in its order.
#[derive(Debug, Clone)]
pub struct FakeFleet {
    pub vehicles: Vec<FakeVehicle>,
}

impl FakeFleet {
    /// A vehicle per drone of `swarm`, on the ground `spacing` metres apart along x.
    pub fn for_swarm(swarm: &Swarm, spacing: f64) -> Self {
        let site = swarm.settings().site;
        FakeFleet {
            vehicles: (0..swarm.len())
                .map(|i| {
                    FakeVehicle::new(
                        swarm.drone(i).vehicle_id,
                        site,
                        [i as f64 * spacing, 0.0, 0.0],
                    )
                })
                .collect(),
        }
    }

    /// Moves every vehicle by `dt` and hands their states to `swarm`.
    pub fn step(&mut self, swarm: &mut Swarm, dt: f64, now_ns: u64) {
        for (i, v) in self.vehicles.iter_mut().enumerate() {
            v.step(dt);
            swarm.handle_state(i, &v.state(now_ns), now_ns);
            swarm.handle_status(i, &v.status(), now_ns);
        }
    }

    /// Delivers `commands` to their vehicles and the acknowledgements and arbiter
    /// events to `swarm`.
    pub fn deliver(&mut self, swarm: &mut Swarm, commands: &[VehicleCommand], now_ns: u64) {
        for c in commands {
            let Some(i) = swarm.index_of_vehicle(c.vehicle_id) else {
                continue;
            };
            if let Some(ack) = self.vehicles[i].handle(c) {
                swarm.handle_ack(i, &ack, now_ns);
            }
            self.deliver_events(swarm, i, now_ns);
        }
    }

    /// Delivers `fences` to their vehicles' arbiters and their answers to `swarm`.
    pub fn deliver_geofences(
        &mut self,
        swarm: &mut Swarm,
        fences: &[Box<GeofenceSet>],
        now_ns: u64,
    ) {
        for g in fences {
            let Some(i) = swarm.index_of_vehicle(g.vehicle_id) else {
                continue;
            };
            self.vehicles[i].handle_geofence(g);
            self.deliver_events(swarm, i, now_ns);
        }
    }

    fn deliver_events(&mut self, swarm: &mut Swarm, i: usize, now_ns: u64) {
        for e in std::mem::take(&mut self.vehicles[i].events) {
            swarm.handle_event(i, &e, now_ns);
        }
    }

    /// A compass heading from a GroundControl yaw (for assertions).
    pub fn heading_of(yaw_ccw: f32) -> f32 {
        heading_of_yaw(yaw_ccw)
    }
}
