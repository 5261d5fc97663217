//! The app's geofence: validated and kept here, enforced by the arbiter for every
//! source, and checked ahead of the vehicle every tick.
//!
//! # Messages
//!
//! | from the app | the engine |
//! |---|---|
//! | GEOFENCE_SET_DATA (an `AppGeofence` from the gateway) | validates every polygon (`shots::fence`: type 0/1, ≥ 3 vertices, as many sub-polygon as polygon vertices, finite coordinates, no self-intersection, non-zero area; at most 8 polygons of 32 vertices, what the arbiter takes); valid → replaces the fence and gives it to the arbiter, GEOFENCE_SET_ACK {count, true} once the arbiter took it; invalid here or at the arbiter → keeps the fence it had, GEOFENCE_SET_ACK {count it has, false} and a SHOTMANAGER_ERROR saying why. No polygon at all is a valid empty fence (cleared). |
//! | GEOFENCE_UPDATE_POLY | action 0 replaces vertex `vertexIndex` of polygon `polygonIndex` (polygon and sub-polygon), 1 inserts one before it (`vertexIndex` = the vertex count appends), 2 removes it; the edited fence is validated again; ack as above (no fence, a bad index or action → negative ack) |
//! | GEOFENCE_CLEAR | clears, GEOFENCE_SET_ACK {0, true} (once the arbiter dropped ours, at once if it had none) |
//!
//! The fence is also cleared when the app disconnects (FACTS.md); the next app to
//! connect is then told with GEOFENCE_CLEAR. Only the engine's own fence goes: the
//! arbiter keeps one fence per source, so a GroundControl keep-in box stays.
//!
//! # The arbiter
//!
//! Every change is published as a `GeofenceSet` (source `ShotEngine`, a fresh
//! `request_id`) on `skymesh/vehicle/{id}/geofence`: the keep-in and keep-out
//! polygons (not the sub-polygons), with `geofence_ceiling_m` / `geofence_floor_m`
//! from the config (the Solo fence has none: large by default); a clear is
//! `enabled = 0` with `target_source` [`NO_HOLDER`] (the engine's own fence only).
//! The arbiter keeps it beside other sources' fences and enforces all of them:
//! it refuses position targets outside and slows every velocity setpoint towards
//! them, whoever sends them. It answers each sample with a `GeofenceUpdated` or
//! `GeofenceInvalid` event carrying the `request_id`, and the app's request is
//! answered from that decision: GEOFENCE_SET_ACK {count, true}, or {count it
//! keeps, false} with a SHOTMANAGER_ERROR and the engine's own fence put back to
//! what the arbiter still holds. No decision within [`FENCE_ANSWER_TIMEOUT_NS`] is
//! answered the same negative way ("the vehicle did not answer"). Requests sent
//! before the previous one's sample left (the same loop turn) are answered by the
//! decision on the sample that carries them. A fence the engine never set is never
//! cleared by it; after a restart, one it set before stays with the arbiter (the
//! safe side) until the app sets or clears a fence.
//!
//! # The predictive check
//!
//! Every tick, while a fence is set and the vehicle is armed, above
//! [`IN_AIR_ALT_M`] with a fresh position, and either flying a shot of ours or in a
//! mode the pilot flies (LOITER, POSHOLD, ALT_HOLD, STABILIZE, ACRO, BRAKE,
//! CIRCLE: not AUTO, RTL, LAND or another source's GUIDED), the engine asks
//! `shots::fence` whether the straight path over the stopping distance
//! (speed² / 2·`geofence_deceleration_mps2`) plus `geofence_latency_s` of flight
//! leaves the allowed area. If it does:
//!
//! 1. a shot ends (exit reason `geofence`: ROI cleared, authority released);
//! 2. GEOFENCE_ACTIVATED goes to the app (once per activation);
//! 3. the engine takes flight authority (its normal source, `shot_engine`: holding
//!    a vehicle at the fence is a safety behaviour, but the shot engine's priority
//!    is the right one — a pilot on the RC or an operator still outranks it), GUIDED,
//!    and a `GoTo` to the hold point: the nearest safe point on the breached
//!    polygon's sub-polygon (if the arbiter refuses that target, `Brake` where the
//!    vehicle is, which the look-ahead keeps inside);
//! 4. once the vehicle is within [`HOLD_REACHED_M`] of it and slower than
//!    [`HOLD_STILL_MPS`]: LOITER and authority released, the sticks are the pilot's.
//!    Meanwhile `GrabFlightAuthority` is re-sent every second (the arbiter's
//!    keep-alive for a source with nothing else to send).
//!
//! A pilot who pushes out again (in LOITER) triggers it again. The hold is given
//! up — logged, and the app told — if GUIDED is not reached within
//! `GUIDED_TIMEOUT_NS` or a hold command is refused; and silently when the pilot
//! changes the mode, a shot starts flying, or the fence is cleared (then LOITER).

use skymesh_ipc_types::arbiter::MAX_FENCE_POLYGONS;
use skymesh_ipc_types::shot_api::ShotEvent;
use skymesh_ipc_types::{
    AppGeofence, Command, CommandAck, CommandKind, CommandSource, FlightMode, GeofenceSet,
    RefusalReason, NO_HOLDER,
};

use super::flight::GUIDED_TIMEOUT_NS;
use super::sitescan::KEEPALIVE_NS;
use super::{Engine, ExitReason};
use crate::shots::fence::{stopping_distance, Fence, FenceError, FenceVerdict, FenceZone};
use crate::shots::{ground_distance_m, GeoPoint, VehicleView};

/// Above this altitude (over home) an armed vehicle is in the air and checked, m.
pub const IN_AIR_ALT_M: f32 = 1.0;
/// The hold point is reached within this horizontal distance, m.
pub const HOLD_REACHED_M: f64 = 1.5;
/// ... and below this speed, m/s.
pub const HOLD_STILL_MPS: f32 = 0.5;
/// A fence change the arbiter has not decided on within this time is answered
/// negatively (the arbiter answers at once when it runs), ns.
pub const FENCE_ANSWER_TIMEOUT_NS: u64 = 2_000_000_000;
/// The most vertices of one polygon the arbiter's `GeofenceSet` carries.
const MAX_VERTICES: usize = skymesh_ipc_types::arbiter::MAX_FENCE_VERTICES;

/// GEOFENCE_UPDATE_POLY actions.
const UPDATE_VERTEX: u8 = 0;
const ADD_VERTEX: u8 = 1;
const REMOVE_VERTEX: u8 = 2;

/// One polygon as the app sent it: `type`, `coord`, `subCoord`.
type AppZone<'a> = (u8, &'a [[f64; 2]], &'a [[f64; 2]]);

/// The engine holding the vehicle at the fence.
#[derive(Debug, Clone)]
pub(crate) struct Hold {
    /// Where to stop; `None` after the `GoTo` was refused: brake where it is.
    target: Option<GeoPoint>,
    /// Acks for commands from this id on belong to the hold.
    first_command_id: u32,
    goto_id: Option<u32>,
    asked_ns: u64,
    guided_seen: bool,
    /// The last `GrabFlightAuthority` (re-sent as the arbiter's keep-alive).
    grabbed_ns: u64,
}

/// A fence change given to the arbiter, waiting for its decision.
#[derive(Debug, Clone)]
struct Awaiting {
    /// The `GeofenceSet::request_id` whose decision answers it.
    request_id: u32,
    /// Polygons of the fence it sets.
    count: u16,
    /// The engine's fence before it (what the arbiter keeps if it refuses).
    previous: Fence,
    previous_published: bool,
    /// The app waits for a GEOFENCE_SET_ACK (not for the clear on its disconnect).
    ack: bool,
    /// Set on the first tick after it was made.
    deadline_ns: Option<u64>,
}

/// The fence and what the engine does with it.
#[derive(Debug, Default)]
pub(crate) struct FenceState {
    fence: Fence,
    /// The arbiter holds a fence of ours (a clear must be published).
    published: bool,
    /// A `GeofenceSet` to publish with the next outputs.
    pending: Option<GeofenceSet>,
    /// Changes waiting for the arbiter's decision, oldest first.
    awaiting: Vec<Awaiting>,
    /// The last `request_id` used.
    last_request: u32,
    hold: Option<Hold>,
    /// The engine cleared the fence on its own; tell the next app (GEOFENCE_CLEAR).
    clear_unannounced: bool,
}

impl FenceState {
    /// The `GeofenceSet` waiting to be published, if any.
    pub fn take_pending(&mut self) -> Option<GeofenceSet> {
        self.pending.take()
    }

    /// The validated fence (empty when none is set).
    pub fn fence(&self) -> &Fence {
        &self.fence
    }

    /// True while the engine holds the vehicle at the fence.
    pub fn holding(&self) -> bool {
        self.hold.is_some()
    }
}

/// Why a GEOFENCE_SET_DATA or UPDATE_POLY was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum Refused {
    #[error("{0} polygons; skymesh takes at most {MAX_FENCE_POLYGONS}")]
    TooManyPolygons(usize),
    #[error("polygon {zone}: {count} vertices; skymesh takes at most {MAX_VERTICES}")]
    TooManyVertices { zone: usize, count: usize },
    #[error(transparent)]
    Invalid(#[from] FenceError),
    #[error("no geofence is set")]
    NoFence,
    #[error("polygon {0} does not exist")]
    NoPolygon(u16),
    #[error("polygon {polygon} has no vertex {vertex}")]
    NoVertex { polygon: u16, vertex: u16 },
    #[error("unknown update action {0}")]
    BadAction(u8),
    #[error("the vehicle refused it: {0}")]
    Arbiter(String),
}

impl Engine {
    /// GEOFENCE_SET_DATA from the gateway's `AppGeofence`.
    pub fn handle_app_geofence(&mut self, g: &AppGeofence, now_ns: u64) {
        self.out.metrics.app_in("geofence_set_data");
        self.app_heard(g.session, now_ns);
        let zones = g
            .polygons()
            .iter()
            .map(|p| (p.kind, p.vertices(), p.sub_vertices()))
            .collect::<Vec<_>>();
        self.geofence_set(&zones);
    }

    /// GEOFENCE_SET_DATA's polygons as `(type, vertices, sub-polygon vertices)`.
    pub(crate) fn geofence_set(&mut self, zones: &[AppZone<'_>]) {
        let built = build(zones.iter().map(|(k, c, s)| {
            FenceZone::from_app(*k, c, s).map_err(|error| FenceError { zone: 0, error })
        }));
        match built {
            Ok(fence) => {
                tracing::info!(polygons = fence.len(), "geofence set");
                self.fence_replace(fence, true);
            }
            Err(e) => self.fence_refused("set", &e),
        }
    }

    /// GEOFENCE_UPDATE_POLY.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn geofence_update(
        &mut self,
        action: u8,
        polygon: u16,
        vertex: u16,
        lat_deg: f64,
        lon_deg: f64,
        sub_lat_deg: f64,
        sub_lon_deg: f64,
    ) {
        let edited = edit(
            self.fence.fence.zones(),
            action,
            polygon,
            vertex,
            [lat_deg, lon_deg],
            [sub_lat_deg, sub_lon_deg],
        )
        .and_then(|zones| build(zones.into_iter().map(Ok)));
        match edited {
            Ok(fence) => {
                tracing::info!(action, polygon, vertex, "geofence polygon updated");
                self.fence_replace(fence, true);
            }
            Err(e) => self.fence_refused("update", &e),
        }
    }

    /// GEOFENCE_CLEAR from the app.
    pub(crate) fn geofence_clear_from_app(&mut self) {
        tracing::info!("geofence cleared by the app");
        self.fence_replace(Fence::empty(), true);
    }

    /// The app went away: its fence goes with it (FACTS.md); other sources' fences
    /// stay with the arbiter.
    pub(crate) fn geofence_app_lost(&mut self) {
        if self.fence.fence.is_empty() {
            return;
        }
        tracing::info!("app gone: the app's geofence cleared");
        self.fence_replace(Fence::empty(), false);
        self.fence.clear_unannounced = true;
    }

    /// An app connected: tell it if the engine cleared the fence meanwhile.
    pub(crate) fn geofence_app_connected(&mut self) {
        if std::mem::take(&mut self.fence.clear_unannounced) && self.fence.fence.is_empty() {
            self.out.app(ShotEvent::GeofenceClear);
        }
    }

    fn fence_ack(&mut self, valid: bool) {
        let count = u16::try_from(self.fence.fence.len()).unwrap_or(u16::MAX);
        self.out.app(ShotEvent::GeofenceSetAck { count, valid });
    }

    /// The arbiter's decision on our `GeofenceSet` `request_id`: answers every change
    /// it carries; a refusal puts the engine's fence back to what the arbiter keeps.
    pub(crate) fn geofence_decided(&mut self, request_id: u32, accepted: bool, detail: &str) {
        let Some(first) = self
            .fence
            .awaiting
            .iter()
            .position(|a| a.request_id == request_id)
        else {
            tracing::debug!(request_id, "a geofence decision for no request of ours");
            return;
        };
        let end = first
            + self.fence.awaiting[first..]
                .iter()
                .take_while(|a| a.request_id == request_id)
                .count();
        let answered: Vec<Awaiting> = self.fence.awaiting.drain(first..end).collect();
        if accepted {
            tracing::debug!(request_id, detail, "the arbiter took the geofence");
            for a in answered.iter().filter(|a| a.ack) {
                self.out.app(ShotEvent::GeofenceSetAck {
                    count: a.count,
                    valid: true,
                });
            }
            return;
        }
        tracing::warn!(request_id, detail, "the arbiter refused the geofence");
        let (previous, published) = (answered[0].previous.clone(), answered[0].previous_published);
        match self.fence.awaiting.get_mut(first) {
            // A later change replaces it anyway: if that one is refused too, the
            // engine goes back to what came before this one.
            Some(next) => {
                next.previous = previous;
                next.previous_published = published;
            }
            None => {
                self.fence.fence = previous;
                self.fence.published = published;
                self.out
                    .metrics
                    .geofence_polygons
                    .set(self.fence.fence.len() as f64);
                if self.fence.fence.is_empty() && self.fence.hold.is_some() {
                    self.hold_end(true);
                }
            }
        }
        let asked = answered.iter().filter(|a| a.ack).count();
        if asked > 0 {
            for _ in 1..asked {
                self.fence_ack(false);
            }
            self.fence_refused("arbiter", &Refused::Arbiter(detail.to_string()));
        }
    }

    /// Changes the arbiter did not decide on in time: answered as refused.
    fn geofence_expire(&mut self, now_ns: u64) {
        for a in &mut self.fence.awaiting {
            a.deadline_ns
                .get_or_insert(now_ns.saturating_add(FENCE_ANSWER_TIMEOUT_NS));
        }
        let late = self
            .fence
            .awaiting
            .first()
            .filter(|a| a.deadline_ns.is_some_and(|d| d <= now_ns))
            .map(|a| a.request_id);
        if let Some(request_id) = late {
            self.geofence_decided(
                request_id,
                false,
                "the vehicle did not answer (autopilot-link not running?)",
            );
        }
    }

    fn fence_refused(&mut self, what: &str, e: &Refused) {
        tracing::warn!(request = what, error = %e, "geofence refused");
        self.fence_ack(false);
        let kept = if self.fence.fence.is_empty() {
            "no geofence is set".to_string()
        } else {
            format!(
                "the previous {}-polygon geofence stays",
                self.fence.fence.len()
            )
        };
        self.out.error(&format!("geofence refused: {e}; {kept}"));
    }

    /// Replaces the fence and queues the `GeofenceSet` for the arbiter; `ack`: the
    /// app is answered once the arbiter decided (at once when there is nothing to
    /// tell the arbiter: a clear while it holds no fence of ours).
    fn fence_replace(&mut self, fence: Fence, ack: bool) {
        self.fence.clear_unannounced = false;
        let previous = std::mem::replace(&mut self.fence.fence, fence);
        let previous_published = self.fence.published;
        self.out
            .metrics
            .geofence_polygons
            .set(self.fence.fence.len() as f64);
        let empty = self.fence.fence.is_empty();
        if empty && self.fence.hold.is_some() {
            tracing::info!("geofence cleared during a hold: LOITER");
            self.hold_end(true);
        }
        if empty && !self.fence.published && self.fence.awaiting.is_empty() {
            if ack {
                self.fence_ack(true);
            }
            return;
        }
        self.fence.last_request = self.fence.last_request.wrapping_add(1).max(1);
        let request_id = self.fence.last_request;
        let mut set = GeofenceSet {
            vehicle_id: self.settings.vehicle_id,
            enabled: u8::from(!empty),
            source: CommandSource::ShotEngine.to_wire(),
            request_id,
            ceiling_m: self.settings.geofence_ceiling_m,
            floor_m: self.settings.geofence_floor_m,
            target_source: NO_HOLDER,
            ..GeofenceSet::default()
        };
        for z in self.fence.fence.zones() {
            // Counts were checked in `build`.
            set.push_polygon(z.kind, &z.polygon);
        }
        // A sample not yet sent is replaced: its changes are answered by this one's
        // decision.
        if let Some(old) = self.fence.pending.replace(set) {
            for a in &mut self.fence.awaiting {
                if a.request_id == old.request_id {
                    a.request_id = request_id;
                }
            }
        }
        self.fence.awaiting.push(Awaiting {
            request_id,
            count: u16::try_from(self.fence.fence.len()).unwrap_or(u16::MAX),
            previous,
            previous_published,
            ack,
            deadline_ns: None,
        });
        self.fence.published = !empty;
    }

    /// A hold, and a change waiting for the arbiter (its timeout), are stepped on
    /// every tick, armed or not (see `Engine::idle_until`).
    pub(crate) fn geofence_needs_ticks(&self) -> bool {
        self.fence.hold.is_some() || !self.fence.awaiting.is_empty()
    }

    /// The predictive check and the hold, once per tick (before the shot steps).
    pub(crate) fn geofence_tick(&mut self, now_ns: u64) {
        self.geofence_expire(now_ns);
        if self.fence.fence.is_empty() {
            return;
        }
        let Some(v) = self.inputs.view(now_ns) else {
            return;
        };
        if self.fence.hold.is_some() {
            self.hold_step(&v, now_ns);
            return;
        }
        if !self.fence_watched(&v) {
            return;
        }
        // Predict with the faster of the measured velocity and what the flying shot
        // asks for: the arbiter's envelope slows a vehicle that a shot keeps pushing
        // at the fence, and that push is what must end the shot.
        let mut v = v;
        let horizontal = |vel: &[f32; 3]| f64::from(vel[0]).hypot(f64::from(vel[1]));
        if let Some(cmd) = self
            .active
            .as_ref()
            .and_then(|a| a.flight.as_ref())
            .and_then(|f| f.commanded_vel)
        {
            if horizontal(&cmd) > horizontal(&v.vel_ned_mps) {
                v.vel_ned_mps = cmd;
            }
        }
        let speed = horizontal(&v.vel_ned_mps);
        let stop = stopping_distance(speed, self.settings.geofence_deceleration_mps2.into());
        let verdict = self
            .fence
            .fence
            .check(&v, stop, self.settings.geofence_latency_s.into());
        if let FenceVerdict::Breach {
            polygon,
            kind,
            hold_point,
        } = verdict
        {
            tracing::warn!(
                polygon,
                %kind,
                speed_mps = speed,
                stopping_m = stop,
                hold_lat = hold_point.lat_deg,
                hold_lon = hold_point.lon_deg,
                "geofence: the vehicle would cross; holding it"
            );
            self.fence_activate(hold_point, now_ns);
        }
    }

    /// Whether the check applies now (see the module doc).
    fn fence_watched(&self, v: &VehicleView) -> bool {
        let Some(status) = self.inputs.status.as_ref() else {
            return false;
        };
        if !status.is_armed() || !status.is_link_up() || !in_air(v) {
            return false;
        }
        self.is_flying()
            || matches!(
                status.flight_mode(),
                FlightMode::Loiter
                    | FlightMode::PosHold
                    | FlightMode::AltHold
                    | FlightMode::Stabilize
                    | FlightMode::Acro
                    | FlightMode::Brake
                    | FlightMode::Circle
            )
    }

    fn fence_activate(&mut self, hold_point: GeoPoint, now_ns: u64) {
        self.out.metrics.geofence_activations.inc();
        if self.active.is_some() {
            self.exit_shot(ExitReason::Geofence);
        }
        self.out.app(ShotEvent::GeofenceActivated);
        let first_command_id = self.out.peek_id();
        self.out.command(Command::GrabFlightAuthority);
        // Asked for even when the last status says GUIDED: it may predate a LOITER
        // (a shot that just ended) that no heartbeat has shown yet.
        self.out.command(Command::SetMode(FlightMode::Guided));
        let goto_id = self
            .out
            .command(goto(&hold_point, self.settings.limits.max_speed_mps));
        self.fence.hold = Some(Hold {
            target: Some(hold_point),
            first_command_id,
            goto_id,
            asked_ns: now_ns,
            guided_seen: false,
            grabbed_ns: now_ns,
        });
    }

    fn hold_step(&mut self, v: &VehicleView, now_ns: u64) {
        if self.is_flying() {
            tracing::info!("geofence hold: a shot is flying now; it takes over");
            self.fence.hold = None;
            return;
        }
        let Some(hold) = self.fence.hold.as_mut() else {
            return;
        };
        // Only a heartbeat from after the GUIDED request tells what became of it.
        let mode = self.inputs.mode_since(hold.asked_ns);
        match mode {
            Some(FlightMode::Guided) => hold.guided_seen = true,
            Some(mode) if hold.guided_seen => {
                tracing::info!(%mode, "geofence hold: the pilot changed the mode; the vehicle is theirs");
                self.fence.hold = None;
                return;
            }
            _ => {}
        }
        if !hold.guided_seen && now_ns.saturating_sub(hold.asked_ns) > GUIDED_TIMEOUT_NS {
            tracing::warn!("geofence hold: the vehicle did not switch to GUIDED; given up");
            self.out
                .error("geofence: could not hold the vehicle (no GUIDED); the arbiter's fence still applies");
            self.fence.hold = None;
            return;
        }
        let speed = v.vel_ned_mps[0].hypot(v.vel_ned_mps[1]);
        let near = hold
            .target
            .is_none_or(|t| ground_distance_m(&v.position, &t) < HOLD_REACHED_M);
        if hold.guided_seen && near && speed < HOLD_STILL_MPS {
            tracing::info!("geofence hold: at the hold point; LOITER, sticks to the pilot");
            self.hold_end(true);
        } else if now_ns.saturating_sub(hold.grabbed_ns) >= KEEPALIVE_NS {
            // A GoTo is one command: keep the arbiter's quiet timeout away.
            hold.grabbed_ns = now_ns;
            self.out.command(Command::GrabFlightAuthority);
        }
    }

    /// Graceful stop: a hold hands the vehicle back in LOITER (the fence stays with
    /// the arbiter).
    pub(crate) fn geofence_shutdown(&mut self) {
        if self.fence.hold.is_some() {
            tracing::info!("stopping during a geofence hold: LOITER");
            self.hold_end(true);
        }
    }

    /// Ends the hold; `loiter` hands the vehicle back in LOITER.
    fn hold_end(&mut self, loiter: bool) {
        if self.fence.hold.take().is_some() && loiter {
            self.out.command(Command::SetMode(FlightMode::Loiter));
            self.out.command(Command::ReleaseFlightAuthority);
        }
    }

    /// An ack of ours: gives the hold up if one of its commands was refused (a
    /// refused `GoTo` for the fence itself → brake where the vehicle is).
    pub(crate) fn geofence_ack(&mut self, ack: &CommandAck, accepted: bool) {
        let Some(hold) = self.fence.hold.as_mut() else {
            return;
        };
        let flight = CommandKind::try_from(ack.kind)
            .ok()
            .and_then(|k| k.authority())
            == Some(skymesh_ipc_types::AuthorityDomain::Flight);
        if accepted || ack.command_id < hold.first_command_id || !flight {
            return;
        }
        let reason = ack.reason().unwrap_or(RefusalReason::None);
        if Some(ack.command_id) == hold.goto_id && reason == RefusalReason::Geofence {
            tracing::warn!(
                detail = ack.detail.as_str(),
                "geofence hold: the hold point was refused; braking where the vehicle is"
            );
            hold.target = None;
            hold.goto_id = None;
            self.out.command(Command::Brake);
            return;
        }
        tracing::warn!(%reason, detail = ack.detail.as_str(), "geofence hold: refused; given up");
        self.out.error(&format!(
            "geofence: could not hold the vehicle ({reason}: {}); the arbiter's fence still applies",
            ack.detail.as_str()
        ));
        self.fence.hold = None;
    }
}

/// Above [`IN_AIR_ALT_M`] (a NaN altitude is not).
pub(crate) fn in_air(v: &VehicleView) -> bool {
    v.position.alt_rel_m > IN_AIR_ALT_M
}

/// A `GoTo` to `p` at `speed_mps`.
fn goto(p: &GeoPoint, speed_mps: f32) -> Command {
    Command::GoTo {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_rel_m: p.alt_rel_m,
        yaw_deg: None,
        speed_mps: Some(speed_mps),
    }
}

/// Zones → a validated fence the arbiter can carry (zone numbers as given).
fn build(
    zones: impl ExactSizeIterator<Item = Result<FenceZone, FenceError>>,
) -> Result<Fence, Refused> {
    if zones.len() > MAX_FENCE_POLYGONS {
        return Err(Refused::TooManyPolygons(zones.len()));
    }
    let mut out = Vec::with_capacity(zones.len());
    for (zone, z) in zones.enumerate() {
        let z = z.map_err(|e| FenceError { zone, ..e })?;
        let count = z.polygon.len().max(z.sub_polygon.len());
        if count > MAX_VERTICES {
            return Err(Refused::TooManyVertices { zone, count });
        }
        out.push(z);
    }
    Ok(Fence::new(out)?)
}

/// `zones` with one vertex updated, added or removed (GEOFENCE_UPDATE_POLY).
fn edit(
    zones: &[FenceZone],
    action: u8,
    polygon: u16,
    vertex: u16,
    point: [f64; 2],
    sub_point: [f64; 2],
) -> Result<Vec<FenceZone>, Refused> {
    if zones.is_empty() {
        return Err(Refused::NoFence);
    }
    let mut zones = zones.to_vec();
    let z = zones
        .get_mut(usize::from(polygon))
        .ok_or(Refused::NoPolygon(polygon))?;
    let i = usize::from(vertex);
    let n = z.polygon.len().min(z.sub_polygon.len());
    let no_vertex = Refused::NoVertex { polygon, vertex };
    match action {
        UPDATE_VERTEX if i < n => {
            z.polygon[i] = point;
            z.sub_polygon[i] = sub_point;
        }
        ADD_VERTEX if i <= n => {
            z.polygon.insert(i, point);
            z.sub_polygon.insert(i, sub_point);
        }
        REMOVE_VERTEX if i < n => {
            z.polygon.remove(i);
            z.sub_polygon.remove(i);
        }
        UPDATE_VERTEX | ADD_VERTEX | REMOVE_VERTEX => return Err(no_vertex),
        other => return Err(Refused::BadAction(other)),
    }
    Ok(zones)
}
