//! MAVLink routing decisions, as mavlink-router makes them. Pure: no I/O, every
//! instant is passed in.
//!
//! Links: the autopilot, our own component (`Local`: autopilot-link's heartbeat)
//! and the configured endpoints. [`Router`] learns from every frame which link a
//! system/component speaks on (the last link wins, so a ground station that moves
//! is followed) and decides where a frame goes:
//!
//! - from the autopilot or from us: every endpoint;
//! - from an endpoint: by its [`Target`]. Broadcast → the autopilot and every other
//!   endpoint; a known component → the link it was last seen on; an unknown
//!   component of a known system, or a whole system → every link that system was
//!   seen on; a system never seen → the autopilot (the default route: components
//!   behind the flight controller are often silent until asked). Never back to the
//!   link it came from.
//! - to `Local` only for the virtual components registered with
//!   [`Router::add_local_component`] (the vision pipeline's gimbals): frames
//!   addressed to one of them go there and nowhere else; broadcast frames and frames
//!   addressed to our whole system are also marked `local` (the hub picks the
//!   message types they handle). Our own component 191 consumes nothing.
//!
//! Sources heard on the autopilot link and our own id are pinned: a frame from an
//! endpoint claiming one of them is a loop (a router on an endpoint echoing our
//! traffic back) and is dropped instead of moving the route.
//!
//! [`AckLedger`] decides whether a COMMAND_ACK from the autopilot answers one of
//! our commands or an endpoint's, so a ground station's acks never reach our
//! AckTracker.

use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

use mavlink_frame::Target;

/// At most this many endpoints (they share an 8-bit destination mask and the stats
/// sample's 384 series).
pub const MAX_ENDPOINTS: usize = 8;
/// Learnt system/component pairs; beyond this new sources are not learnt (their
/// traffic is still routed, by the default rules).
pub const MAX_ROUTES: usize = 512;

/// Where a frame came from or goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Link {
    Autopilot,
    /// autopilot-link itself (system id, component 191).
    Local,
    /// Index into the configured endpoints (< [`MAX_ENDPOINTS`]).
    Endpoint(u8),
}

/// The links a frame is sent to.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Destinations {
    pub autopilot: bool,
    /// Bit `i` = endpoint `i`.
    pub endpoints: u8,
    /// Our virtual components (see [`Router::add_local_component`]).
    pub local: bool,
}

impl Destinations {
    fn add(&mut self, link: Link) {
        match link {
            Link::Autopilot => self.autopilot = true,
            Link::Endpoint(i) => self.endpoints |= 1 << i,
            Link::Local => {}
        }
    }

    fn remove(&mut self, link: Link) {
        match link {
            Link::Autopilot => self.autopilot = false,
            Link::Endpoint(i) => self.endpoints &= !(1 << i),
            Link::Local => {}
        }
    }

    pub fn is_empty(&self) -> bool {
        !self.autopilot && self.endpoints == 0 && !self.local
    }

    /// The endpoint indices in this set, ascending.
    pub fn endpoints(&self) -> impl Iterator<Item = u8> + '_ {
        (0..MAX_ENDPOINTS as u8).filter(|i| self.endpoints & (1 << i) != 0)
    }
}

/// What learning a frame's source found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Learned {
    /// Recorded (or already known) on this link: route the frame.
    Ok,
    /// The source is pinned to the autopilot or to us: drop the frame.
    Loop,
}

/// The routing table; see the module documentation.
#[derive(Debug)]
pub struct Router {
    endpoints: u8,
    local: (u8, u8),
    /// (system, component) → the link it was last heard on.
    seen: HashMap<(u8, u8), Link>,
    /// Components of our system served locally (virtual gimbals), pinned to `Local`.
    virtual_components: Vec<u8>,
}

impl Router {
    /// `endpoints` configured endpoints (at most [`MAX_ENDPOINTS`]); `local` is our own
    /// (system, component).
    pub fn new(endpoints: usize, local: (u8, u8)) -> Router {
        let endpoints = endpoints.min(MAX_ENDPOINTS) as u8;
        let mut seen = HashMap::new();
        seen.insert(local, Link::Local);
        Router {
            endpoints,
            local,
            seen,
            virtual_components: Vec::new(),
        }
    }

    /// Serves `component` of our system locally: frames addressed to it are
    /// delivered to `Local` (never to the autopilot), and endpoints claiming it are
    /// loops.
    pub fn add_local_component(&mut self, component: u8) {
        self.seen.insert((self.local.0, component), Link::Local);
        if !self.virtual_components.contains(&component) {
            self.virtual_components.push(component);
        }
    }

    fn all_endpoints(&self) -> u8 {
        ((1u16 << self.endpoints) - 1) as u8
    }

    /// Records that `source` spoke on `link`.
    pub fn learn(&mut self, link: Link, source: (u8, u8)) -> Learned {
        if source.0 == 0 {
            return Learned::Ok;
        }
        match (self.seen.get(&source).copied(), link) {
            (Some(l), _) if l == link => Learned::Ok,
            (Some(Link::Local), _) => Learned::Loop,
            (Some(Link::Autopilot), Link::Endpoint(_)) => Learned::Loop,
            (None, _) if self.seen.len() >= MAX_ROUTES && link != Link::Autopilot => Learned::Ok,
            _ => {
                self.seen.insert(source, link);
                Learned::Ok
            }
        }
    }

    /// The link `(system, component)` was last heard on.
    pub fn link_of(&self, system: u8, component: u8) -> Option<Link> {
        self.seen.get(&(system, component)).copied()
    }

    /// Where a frame from `from` addressed to `target` goes.
    pub fn route(&self, from: Link, target: Target) -> Destinations {
        let mut to = Destinations::default();
        match from {
            Link::Autopilot | Link::Local => to.endpoints = self.all_endpoints(),
            Link::Endpoint(_) => match target {
                Target::Broadcast => {
                    to.autopilot = true;
                    to.endpoints = self.all_endpoints();
                    to.local = !self.virtual_components.is_empty();
                }
                Target::Component(s, c) if self.seen.contains_key(&(s, c)) => {
                    to.add(self.seen[&(s, c)]);
                    to.local = s == self.local.0 && self.virtual_components.contains(&c);
                }
                Target::Component(s, _) | Target::System(s) => {
                    if matches!(target, Target::System(_)) && s == self.local.0 {
                        to.local = !self.virtual_components.is_empty();
                    }
                    let mut known = false;
                    for (_, link) in self.seen.iter().filter(|((sys, _), _)| *sys == s) {
                        known = true;
                        to.add(*link);
                    }
                    if !known {
                        to.autopilot = true;
                    }
                }
            },
        }
        to.remove(from);
        to
    }

    /// Our own (system, component).
    pub fn local(&self) -> (u8, u8) {
        self.local
    }
}

/// Whose command a COMMAND_ACK answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AckOwner {
    /// One of ours (or nobody's we know of: the AckTracker ignores unexpected acks).
    Us,
    /// A command an endpoint sent: keep it away from the AckTracker.
    Endpoint,
}

/// How long [`AckLedger`] remembers a command the autopilot has not answered.
pub const LEDGER_TTL: Duration = Duration::from_secs(5);
const LEDGER_CAPACITY: usize = 64;
/// `MAV_RESULT_IN_PROGRESS`: a final answer follows.
const IN_PROGRESS: u8 = 5;

#[derive(Debug, Clone, Copy)]
struct Pending {
    command: u16,
    ours: bool,
    at: Instant,
}

/// Attributes each COMMAND_ACK from the autopilot to us or to an endpoint.
///
/// ArduPilot fills COMMAND_ACK's `target_system`/`target_component` (MAVLink 2
/// extensions) with the sender of the command: that decides. Autopilots that leave
/// them 0 (older firmware, vehicle-sim) are answered in the order their commands
/// arrived, so an ack goes to the oldest unanswered sender of that MAV_CMD (every
/// write to the autopilot passes one writer, which records it here). Entries expire
/// after [`LEDGER_TTL`], so a command the autopilot never answered cannot shift the
/// attribution for long.
#[derive(Debug)]
pub struct AckLedger {
    me: (u8, u8),
    /// Commands written to the autopilot and not answered yet, oldest first.
    pending: VecDeque<Pending>,
}

impl AckLedger {
    pub fn new(me: (u8, u8)) -> AckLedger {
        AckLedger {
            me,
            pending: VecDeque::new(),
        }
    }

    /// A COMMAND_LONG/COMMAND_INT with `command` was written to the autopilot.
    pub fn sent(&mut self, command: u16, ours: bool, now: Instant) {
        self.expire(now);
        if self.pending.len() >= LEDGER_CAPACITY {
            self.pending.pop_front();
        }
        self.pending.push_back(Pending {
            command,
            ours,
            at: now,
        });
    }

    fn expire(&mut self, now: Instant) {
        while self
            .pending
            .front()
            .is_some_and(|p| now.duration_since(p.at) > LEDGER_TTL)
        {
            self.pending.pop_front();
        }
    }

    /// Whose command the COMMAND_ACK (`command`, `result`, `target`) answers.
    pub fn on_ack(&mut self, command: u16, result: u8, target: (u8, u8), now: Instant) -> AckOwner {
        self.expire(now);
        let final_answer = result != IN_PROGRESS;
        let ours = if target.0 != 0 {
            target.0 == self.me.0 && (target.1 == 0 || target.1 == self.me.1)
        } else {
            match self.pending.iter().find(|p| p.command == command) {
                Some(p) => p.ours,
                None => return AckOwner::Us,
            }
        };
        if final_answer {
            if let Some(i) = self
                .pending
                .iter()
                .position(|p| p.command == command && p.ours == ours)
            {
                self.pending.remove(i);
            }
        }
        if ours {
            AckOwner::Us
        } else {
            AckOwner::Endpoint
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: (u8, u8) = (1, 191);
    const AP: (u8, u8) = (1, 1);
    const GCS: (u8, u8) = (255, 190);
    const E0: Link = Link::Endpoint(0);
    const E1: Link = Link::Endpoint(1);
    const E2: Link = Link::Endpoint(2);

    fn router() -> Router {
        let mut r = Router::new(3, US);
        assert_eq!(r.learn(Link::Autopilot, AP), Learned::Ok);
        r
    }

    fn set(autopilot: bool, endpoints: &[u8]) -> Destinations {
        Destinations {
            autopilot,
            endpoints: endpoints.iter().fold(0, |m, i| m | 1 << i),
            local: false,
        }
    }

    #[test]
    fn virtual_components_are_served_locally_and_never_by_the_autopilot() {
        let mut r = router();
        // Without virtual components nothing is local.
        assert!(!r.route(E0, Target::Broadcast).local);
        r.add_local_component(154);
        let to = r.route(E0, Target::Component(1, 154));
        assert_eq!(
            to,
            Destinations {
                local: true,
                ..Destinations::default()
            }
        );
        // Broadcast and our system: local too, plus the usual links.
        let b = r.route(E0, Target::Broadcast);
        assert!(b.local && b.autopilot);
        let sys = r.route(E0, Target::System(1));
        assert!(sys.local && sys.autopilot);
        // Our own component 191 still consumes nothing.
        assert!(!r.route(E0, Target::Component(1, 191)).local);
        // Another system's 154 is not ours.
        assert!(!r.route(E0, Target::Component(7, 154)).local);
        // An endpoint claiming a virtual component is a loop.
        assert_eq!(r.learn(E0, (1, 154)), Learned::Loop);
        // Nor is it taken over by the autopilot link (a colliding real component).
        assert_eq!(r.learn(Link::Autopilot, (1, 154)), Learned::Loop);
        assert!(r.route(E0, Target::Component(1, 154)).local);
    }

    #[test]
    fn autopilot_and_local_traffic_goes_to_every_endpoint() {
        let r = router();
        for target in [
            Target::Broadcast,
            Target::Component(255, 190),
            Target::System(9),
        ] {
            assert_eq!(r.route(Link::Autopilot, target), set(false, &[0, 1, 2]));
            assert_eq!(r.route(Link::Local, target), set(false, &[0, 1, 2]));
        }
        assert_eq!(
            Router::new(0, US).route(Link::Autopilot, Target::Broadcast),
            set(false, &[])
        );
    }

    #[test]
    fn broadcast_from_an_endpoint_goes_everywhere_but_back() {
        let r = router();
        assert_eq!(r.route(E1, Target::Broadcast), set(true, &[0, 2]));
    }

    #[test]
    fn targeted_frames_follow_what_was_learnt() {
        let mut r = router();
        r.learn(E0, GCS);
        r.learn(E2, (7, 1));
        // The vehicle lives behind the autopilot link.
        assert_eq!(r.route(E0, Target::Component(1, 1)), set(true, &[]));
        assert_eq!(r.route(E0, Target::System(1)), set(true, &[]));
        // A silent component of the vehicle (a gimbal behind the flight controller).
        assert_eq!(r.route(E0, Target::Component(1, 154)), set(true, &[]));
        // A system seen only on endpoint 2 is reached there, not on the autopilot.
        assert_eq!(r.route(E0, Target::Component(7, 1)), set(false, &[2]));
        assert_eq!(r.route(E1, Target::System(7)), set(false, &[2]));
        // The ground station's own answers find it.
        assert_eq!(r.route(E2, Target::Component(255, 190)), set(false, &[0]));
    }

    #[test]
    fn never_back_to_the_sender() {
        let mut r = router();
        r.learn(E0, GCS);
        r.learn(E0, (255, 191));
        assert_eq!(r.route(E0, Target::Component(255, 191)), set(false, &[]));
        assert_eq!(r.route(E0, Target::System(255)), set(false, &[]));
    }

    #[test]
    fn unknown_targets_take_the_default_route_to_the_autopilot() {
        let r = router();
        assert_eq!(r.route(E1, Target::Component(42, 1)), set(true, &[]));
        assert_eq!(r.route(E1, Target::System(42)), set(true, &[]));
    }

    #[test]
    fn frames_for_us_are_not_routed() {
        let r = router();
        // (1, 191) is us; system 1 as a whole is the autopilot (and us).
        assert_eq!(r.route(E0, Target::Component(1, 191)), set(false, &[]));
        assert_eq!(r.route(E0, Target::System(1)), set(true, &[]));
    }

    #[test]
    fn a_source_that_moves_is_followed() {
        let mut r = router();
        r.learn(E0, GCS);
        r.learn(E1, GCS);
        assert_eq!(r.link_of(255, 190), Some(E1));
        assert_eq!(r.route(E2, Target::Component(255, 190)), set(false, &[1]));
    }

    #[test]
    fn the_autopilot_and_we_are_pinned_against_loops() {
        let mut r = router();
        assert_eq!(r.learn(E0, AP), Learned::Loop);
        assert_eq!(r.learn(E0, US), Learned::Loop);
        assert_eq!(r.link_of(1, 1), Some(Link::Autopilot));
        // An endpoint that spoke first loses the id to the autopilot.
        let mut r = Router::new(2, US);
        r.learn(E0, (2, 1));
        assert_eq!(r.learn(Link::Autopilot, (2, 1)), Learned::Ok);
        assert_eq!(r.link_of(2, 1), Some(Link::Autopilot));
        // System 0 is not an address.
        assert_eq!(r.learn(E0, (0, 0)), Learned::Ok);
        assert_eq!(r.link_of(0, 0), None);
    }

    #[test]
    fn the_table_is_bounded() {
        let mut r = Router::new(1, US);
        for s in 1..=255u8 {
            for c in 0..3u8 {
                r.learn(E0, (s, c));
            }
        }
        assert!(r.seen.len() <= MAX_ROUTES);
        // The autopilot is always learnt.
        r.learn(Link::Autopilot, (250, 250));
        assert_eq!(r.link_of(250, 250), Some(Link::Autopilot));
    }

    #[test]
    fn acks_with_targets_are_attributed_by_target() {
        let t = Instant::now();
        let mut l = AckLedger::new(US);
        l.sent(176, false, t);
        l.sent(176, true, t);
        assert_eq!(l.on_ack(176, 0, GCS, t), AckOwner::Endpoint);
        assert_eq!(l.on_ack(176, 0, (1, 191), t), AckOwner::Us);
        assert_eq!(l.on_ack(176, 0, (1, 0), t), AckOwner::Us);
        assert_eq!(
            l.on_ack(176, 0, (1, 1), t),
            AckOwner::Endpoint,
            "another component"
        );
        assert!(l.pending.is_empty());
    }

    #[test]
    fn acks_without_targets_are_attributed_in_order() {
        let t = Instant::now();
        let mut l = AckLedger::new(US);
        l.sent(176, false, t);
        l.sent(400, true, t);
        l.sent(176, true, t);
        assert_eq!(l.on_ack(400, 0, (0, 0), t), AckOwner::Us);
        // In progress keeps the entry: the final answer is the endpoint's too.
        assert_eq!(l.on_ack(176, IN_PROGRESS, (0, 0), t), AckOwner::Endpoint);
        assert_eq!(l.on_ack(176, 0, (0, 0), t), AckOwner::Endpoint);
        assert_eq!(l.on_ack(176, 0, (0, 0), t), AckOwner::Us);
        // Nothing pending: let the tracker decide.
        assert_eq!(l.on_ack(176, 0, (0, 0), t), AckOwner::Us);
    }

    #[test]
    fn unanswered_commands_expire() {
        let t = Instant::now();
        let mut l = AckLedger::new(US);
        l.sent(176, false, t);
        let later = t + LEDGER_TTL + Duration::from_millis(1);
        l.sent(176, true, later);
        assert_eq!(l.on_ack(176, 0, (0, 0), later), AckOwner::Us);
        for _ in 0..2 * LEDGER_CAPACITY {
            l.sent(22, false, later);
        }
        assert_eq!(l.pending.len(), LEDGER_CAPACITY);
    }
}
