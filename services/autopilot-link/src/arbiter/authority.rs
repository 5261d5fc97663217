//! Who may command the vehicle: one flight holder and one payload holder. Pure.
//!
//! Rules (each applies to flight and payload separately):
//! - A grab, or any command of that domain, succeeds when nobody holds the
//!   authority, when the sender already holds it, or when the sender outranks the
//!   holder ([`CommandSource::priority`]) — the holder is then pre-empted. Otherwise
//!   it is refused `NoAuthority`. Commands therefore grab implicitly, exactly as an
//!   explicit grab would; an explicit grab only adds the answer "you hold it now".
//! - The holder keeps it while it is heard from: any command or grab of that domain
//!   within the quiet timeout (re-sending the grab is the keep-alive of a source that
//!   has nothing to command). Silence for the timeout → nobody holds it (`Timeout`).
//! - An emergency stop is owned by its engagers: each source that sends one is
//!   recorded (with the command id of its first stop; one engagement per source).
//!   While any engagement is in force the safety source holds flight authority, no
//!   timeout applies, and releasing authority (safety's included) changes nothing.
//!   [`Authority::release_emergency`] withdraws the sender's own engagement; the stop
//!   ends when the last one is withdrawn, or at once on
//!   [`Authority::clear_emergency`] (the arbiter admits that only from operator or
//!   safety). Either way flight authority is then released (`Released`).
//! - Autopilot link lost → nobody holds either authority (`LinkLost`), except that an
//!   emergency stop stays in force.

use skymesh_ipc_types::{
    AuthorityChange, AuthorityDomain, AuthorityState, CommandSource, NO_HOLDER,
};

/// One authority (flight or payload).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    pub holder: Option<CommandSource>,
    pub previous: Option<CommandSource>,
    pub change: AuthorityChange,
    /// `CLOCK_MONOTONIC` ns of the last change.
    pub since_ns: u64,
    /// When the holder was last heard from.
    heard_ns: u64,
}

impl Default for Slot {
    fn default() -> Self {
        Slot {
            holder: None,
            previous: None,
            change: AuthorityChange::None,
            since_ns: 0,
            heard_ns: 0,
        }
    }
}

/// Whether `source` may act in a domain, and what acting would change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Claim {
    /// It already holds the authority.
    Holds,
    /// Nobody holds it: acting grants it.
    Free,
    /// It outranks the holder, who would be pre-empted.
    Outranks(CommandSource),
    /// The holder outranks or equals it (refused).
    HeldBy(CommandSource),
}

impl Slot {
    pub fn claim(&self, source: CommandSource) -> Claim {
        match self.holder {
            None => Claim::Free,
            Some(h) if h == source => Claim::Holds,
            Some(h) if source.priority() > h.priority() => Claim::Outranks(h),
            Some(h) => Claim::HeldBy(h),
        }
    }

    fn set(&mut self, holder: Option<CommandSource>, change: AuthorityChange, now_ns: u64) {
        self.previous = self.holder;
        self.holder = holder;
        self.change = change;
        self.since_ns = now_ns;
        self.heard_ns = now_ns;
    }
}

/// A change to publish (AuthorityState, event, gauge, log).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Change {
    pub domain: AuthorityDomain,
    pub from: Option<CommandSource>,
    pub to: Option<CommandSource>,
    pub change: AuthorityChange,
}

/// Flight and payload authority of one vehicle.
#[derive(Debug, Clone)]
pub struct Authority {
    flight: Slot,
    payload: Slot,
    /// The emergency stop's engagers: the command id of each source's first stop
    /// (index = source wire value). In force while any is set.
    engagers: [Option<u32>; CommandSource::ALL.len()],
    timeout_ns: u64,
}

/// One source's emergency stop in force.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Engagement {
    pub source: CommandSource,
    /// The id of the source's first stop command.
    pub command_id: u32,
}

/// What [`Authority::release_emergency`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Released {
    /// The sender had no stop in force; nothing changed.
    NotEngaged,
    /// The sender's stop is withdrawn; these sources still hold the vehicle.
    Remaining(Vec<CommandSource>),
    /// The sender was the last engager: the stop ended and safety's flight
    /// authority was released.
    Ended(Change),
}

impl Authority {
    pub fn new(timeout_ns: u64) -> Self {
        Authority {
            flight: Slot::default(),
            payload: Slot::default(),
            engagers: [None; CommandSource::ALL.len()],
            timeout_ns,
        }
    }

    pub fn slot(&self, domain: AuthorityDomain) -> &Slot {
        match domain {
            AuthorityDomain::Flight => &self.flight,
            AuthorityDomain::Payload => &self.payload,
        }
    }

    fn slot_mut(&mut self, domain: AuthorityDomain) -> &mut Slot {
        match domain {
            AuthorityDomain::Flight => &mut self.flight,
            AuthorityDomain::Payload => &mut self.payload,
        }
    }

    pub fn in_emergency(&self) -> bool {
        self.engagers.iter().any(Option::is_some)
    }

    /// The stops in force, in source wire order.
    pub fn engagements(&self) -> Vec<Engagement> {
        CommandSource::ALL
            .iter()
            .filter_map(|&source| {
                self.engagers[usize::from(source.to_wire())]
                    .map(|command_id| Engagement { source, command_id })
            })
            .collect()
    }

    /// The engagers as a bitmask (`1 << source.to_wire()`).
    pub fn emergency_sources(&self) -> u8 {
        CommandSource::ALL
            .iter()
            .filter(|s| self.engagers[usize::from(s.to_wire())].is_some())
            .fold(0, |m, s| m | 1 << s.to_wire())
    }

    pub fn claim(&self, domain: AuthorityDomain, source: CommandSource) -> Claim {
        self.slot(domain).claim(source)
    }

    /// `source` acted in `domain` (a command or grab that the arbiter let through):
    /// refreshes the holder, or grants / pre-empts as [`Claim`] said.
    pub fn act(
        &mut self,
        domain: AuthorityDomain,
        source: CommandSource,
        now_ns: u64,
    ) -> Option<Change> {
        let slot = self.slot_mut(domain);
        let change = match slot.claim(source) {
            Claim::Holds => {
                slot.heard_ns = now_ns;
                return None;
            }
            Claim::HeldBy(_) => return None,
            Claim::Free => AuthorityChange::Granted,
            Claim::Outranks(_) => AuthorityChange::Preempted,
        };
        Some(self.transfer(domain, Some(source), change, now_ns))
    }

    fn transfer(
        &mut self,
        domain: AuthorityDomain,
        to: Option<CommandSource>,
        change: AuthorityChange,
        now_ns: u64,
    ) -> Change {
        let slot = self.slot_mut(domain);
        let from = slot.holder;
        slot.set(to, change, now_ns);
        Change {
            domain,
            from,
            to,
            change,
        }
    }

    /// `source` gives `domain` back. `None` if it did not hold it, and for flight
    /// authority during an emergency stop: safety keeps it until the stop ends
    /// (releasing authority never ends a stop).
    pub fn release(
        &mut self,
        domain: AuthorityDomain,
        source: CommandSource,
        now_ns: u64,
    ) -> Option<Change> {
        if self.slot(domain).holder != Some(source)
            || (domain == AuthorityDomain::Flight && self.in_emergency())
        {
            return None;
        }
        Some(self.transfer(domain, None, AuthorityChange::Released, now_ns))
    }

    /// `source` engages an emergency stop (`command_id`: its stop command; a source
    /// already engaged keeps its first id): safety takes flight authority and keeps
    /// it while any engagement is in force.
    pub fn emergency(
        &mut self,
        source: CommandSource,
        command_id: u32,
        now_ns: u64,
    ) -> Option<Change> {
        let already = self.in_emergency() && self.flight.holder == Some(CommandSource::Safety);
        self.engagers[usize::from(source.to_wire())].get_or_insert(command_id);
        (!already).then(|| {
            self.transfer(
                AuthorityDomain::Flight,
                Some(CommandSource::Safety),
                AuthorityChange::Emergency,
                now_ns,
            )
        })
    }

    /// `source` withdraws its own emergency stop (never another's).
    pub fn release_emergency(&mut self, source: CommandSource, now_ns: u64) -> Released {
        if self.engagers[usize::from(source.to_wire())]
            .take()
            .is_none()
        {
            return Released::NotEngaged;
        }
        if self.in_emergency() {
            return Released::Remaining(self.engagements().iter().map(|e| e.source).collect());
        }
        Released::Ended(self.end_emergency(now_ns))
    }

    /// Ends the emergency stop whoever engaged it (the arbiter admits this only from
    /// operator or safety). `None` when no stop was in force; else the stops that
    /// were in force and the release of safety's flight authority.
    pub fn clear_emergency(&mut self, now_ns: u64) -> Option<(Vec<Engagement>, Change)> {
        let was = self.engagements();
        if was.is_empty() {
            return None;
        }
        self.engagers = [None; CommandSource::ALL.len()];
        Some((was, self.end_emergency(now_ns)))
    }

    fn end_emergency(&mut self, now_ns: u64) -> Change {
        self.transfer(
            AuthorityDomain::Flight,
            None,
            AuthorityChange::Released,
            now_ns,
        )
    }

    /// At start: the stops in force when the service last saved its state are in
    /// force again (safety holds flight authority). Nothing else is restored: nobody
    /// else holds authority after a restart.
    pub fn restore_emergency(&mut self, engaged: &[Engagement], now_ns: u64) -> Option<Change> {
        let mut change = None;
        for e in engaged {
            change = self.emergency(e.source, e.command_id, now_ns).or(change);
        }
        change
    }

    /// The link to the autopilot went down: nobody holds authority (an emergency
    /// stop stays in force with safety holding flight authority).
    pub fn link_lost(&mut self, now_ns: u64) -> Vec<Change> {
        let mut changes = Vec::new();
        for domain in [AuthorityDomain::Flight, AuthorityDomain::Payload] {
            let emergency_hold = domain == AuthorityDomain::Flight && self.in_emergency();
            if self.slot(domain).holder.is_some() && !emergency_hold {
                changes.push(self.transfer(domain, None, AuthorityChange::LinkLost, now_ns));
            }
        }
        changes
    }

    /// Holders silent for the quiet timeout lose their authority.
    pub fn poll(&mut self, now_ns: u64) -> Vec<Change> {
        let mut changes = Vec::new();
        for domain in [AuthorityDomain::Flight, AuthorityDomain::Payload] {
            if self.deadline(domain).is_some_and(|d| now_ns >= d) {
                changes.push(self.transfer(domain, None, AuthorityChange::Timeout, now_ns));
            }
        }
        changes
    }

    fn deadline(&self, domain: AuthorityDomain) -> Option<u64> {
        let slot = self.slot(domain);
        let exempt = domain == AuthorityDomain::Flight && self.in_emergency();
        (slot.holder.is_some() && !exempt).then(|| slot.heard_ns.saturating_add(self.timeout_ns))
    }

    /// When [`Authority::poll`] would next change something.
    pub fn next_deadline(&self) -> Option<u64> {
        [AuthorityDomain::Flight, AuthorityDomain::Payload]
            .into_iter()
            .filter_map(|d| self.deadline(d))
            .min()
    }

    /// The sample to publish (header left for the publisher).
    pub fn state(&self, vehicle_id: u8) -> AuthorityState {
        let wire = |s: Option<CommandSource>| s.map_or(NO_HOLDER, CommandSource::to_wire);
        AuthorityState {
            vehicle_id,
            flight_holder: wire(self.flight.holder),
            flight_previous: wire(self.flight.previous),
            flight_change: self.flight.change.to_wire(),
            payload_holder: wire(self.payload.holder),
            payload_previous: wire(self.payload.previous),
            payload_change: self.payload.change.to_wire(),
            emergency: u8::from(self.in_emergency()),
            flight_since_ns: self.flight.since_ns,
            payload_since_ns: self.payload.since_ns,
            emergency_sources: self.emergency_sources(),
            ..AuthorityState::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use AuthorityDomain::{Flight, Payload};
    use CommandSource::*;

    const S: u64 = 1_000_000_000;

    #[test]
    fn grant_preempt_and_refuse_follow_priority() {
        let mut a = Authority::new(5 * S);
        assert_eq!(a.claim(Flight, ShotEngine), Claim::Free);
        let c = a.act(Flight, ShotEngine, S).unwrap();
        assert_eq!(
            (c.from, c.to, c.change),
            (None, Some(ShotEngine), AuthorityChange::Granted)
        );
        assert_eq!(a.claim(Flight, ShotEngine), Claim::Holds);
        assert_eq!(
            a.act(Flight, ShotEngine, 2 * S),
            None,
            "a holder is only refreshed"
        );
        assert_eq!(a.claim(Flight, Vision), Claim::HeldBy(ShotEngine));
        assert_eq!(a.act(Flight, Vision, 2 * S), None);
        assert_eq!(a.claim(Flight, Operator), Claim::Outranks(ShotEngine));
        let c = a.act(Flight, Operator, 3 * S).unwrap();
        assert_eq!(c.change, AuthorityChange::Preempted);
        let st = a.state(4);
        assert_eq!(st.vehicle_id, 4);
        assert_eq!(st.flight(), Some(Operator));
        assert_eq!(st.flight_previous, ShotEngine.to_wire());
        assert_eq!(st.flight_change, AuthorityChange::Preempted.to_wire());
        assert_eq!(st.flight_since_ns, 3 * S);
        assert_eq!(st.payload(), None, "payload is separate");
        assert_eq!(a.claim(Payload, Vision), Claim::Free);
    }

    #[test]
    fn silence_times_out_and_activity_keeps_authority() {
        let mut a = Authority::new(5 * S);
        a.act(Flight, Imc, S);
        a.act(Payload, Vision, S);
        assert_eq!(a.next_deadline(), Some(6 * S));
        a.act(Flight, Imc, 4 * S);
        assert_eq!(a.next_deadline(), Some(6 * S), "payload is due first");
        let c = a.poll(6 * S);
        assert_eq!(c.len(), 1);
        assert_eq!(
            (c[0].domain, c[0].change),
            (Payload, AuthorityChange::Timeout)
        );
        assert!(a.poll(8 * S).is_empty());
        let c = a.poll(9 * S);
        assert_eq!((c[0].domain, c[0].from), (Flight, Some(Imc)));
        assert_eq!(a.next_deadline(), None);
    }

    #[test]
    fn release_only_by_the_holder() {
        let mut a = Authority::new(5 * S);
        a.act(Flight, DjiDrc, S);
        assert_eq!(a.release(Flight, Vision, S), None);
        let c = a.release(Flight, DjiDrc, 2 * S).unwrap();
        assert_eq!(c.change, AuthorityChange::Released);
        assert_eq!(a.slot(Flight).holder, None);
        assert_eq!(a.slot(Flight).previous, Some(DjiDrc));
    }

    #[test]
    fn emergency_holds_until_every_engager_releases_and_survives_link_loss() {
        let mut a = Authority::new(5 * S);
        a.act(Flight, ManualRc, S);
        a.act(Payload, Vision, S);
        let c = a.emergency(DjiDrc, 11, 2 * S).unwrap();
        assert_eq!((c.from, c.to), (Some(ManualRc), Some(Safety)));
        assert_eq!(
            a.emergency(DjiDrc, 12, 2 * S),
            None,
            "a second stop changes nothing"
        );
        assert_eq!(a.emergency(Operator, 40, 2 * S), None);
        assert!(a.in_emergency());
        assert_eq!(
            a.engagements(),
            [
                Engagement {
                    source: DjiDrc,
                    command_id: 11
                },
                Engagement {
                    source: Operator,
                    command_id: 40
                },
            ],
            "one engagement per source, its first command id"
        );
        let st = a.state(1);
        assert_eq!(st.emergency, 1);
        assert!(st.emergency_by(DjiDrc) && st.emergency_by(Operator) && !st.emergency_by(Safety));
        assert_eq!(a.next_deadline(), Some(6 * S), "only payload can time out");
        a.poll(100 * S);
        assert_eq!(a.slot(Flight).holder, Some(Safety));
        let lost = a.link_lost(101 * S);
        assert!(
            lost.is_empty(),
            "payload already timed out, flight held: {lost:?}"
        );
        assert_eq!(a.release(Flight, ManualRc, 102 * S), None);
        assert_eq!(
            a.release(Flight, Safety, 102 * S),
            None,
            "releasing authority never ends a stop, not even safety's"
        );
        assert_eq!(a.release_emergency(Vision, 103 * S), Released::NotEngaged);
        assert_eq!(
            a.release_emergency(DjiDrc, 103 * S),
            Released::Remaining(vec![Operator])
        );
        assert_eq!(a.release_emergency(DjiDrc, 103 * S), Released::NotEngaged);
        assert!(a.in_emergency());
        assert_eq!(a.slot(Flight).holder, Some(Safety));
        let Released::Ended(c) = a.release_emergency(Operator, 104 * S) else {
            panic!("the last engager ends the stop");
        };
        assert_eq!(
            (c.from, c.to, c.change),
            (Some(Safety), None, AuthorityChange::Released)
        );
        assert!(!a.in_emergency());
        assert_eq!((a.state(1).emergency, a.state(1).emergency_sources), (0, 0));
    }

    #[test]
    fn clear_ends_every_engagement_and_restore_brings_them_back() {
        let mut a = Authority::new(5 * S);
        assert_eq!(a.clear_emergency(S), None);
        a.emergency(SwarmQueue, 1, S);
        a.emergency(ShotEngine, 2, S);
        let (was, c) = a.clear_emergency(2 * S).unwrap();
        assert_eq!(
            was.iter().map(|e| e.source).collect::<Vec<_>>(),
            [ShotEngine, SwarmQueue]
        );
        assert_eq!((c.to, c.change), (None, AuthorityChange::Released));
        assert!(!a.in_emergency());

        let mut b = Authority::new(5 * S);
        let c = b.restore_emergency(&was, 3 * S).unwrap();
        assert_eq!((c.to, c.change), (Some(Safety), AuthorityChange::Emergency));
        assert_eq!(b.engagements(), was);
        assert_eq!(b.next_deadline(), None);
        assert_eq!(b.restore_emergency(&[], 3 * S), None);
    }

    #[test]
    fn link_loss_clears_both() {
        let mut a = Authority::new(5 * S);
        a.act(Flight, SwarmQueue, S);
        a.act(Payload, ShotEngine, S);
        let c = a.link_lost(2 * S);
        assert_eq!(c.len(), 2);
        assert!(c
            .iter()
            .all(|c| c.change == AuthorityChange::LinkLost && c.to.is_none()));
        assert_eq!(a.claim(Flight, Vision), Claim::Free);
    }
}
