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
//! - An emergency stop gives flight authority to the safety source until safety
//!   releases it; no timeout applies meanwhile.
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
    emergency: bool,
    timeout_ns: u64,
}

impl Authority {
    pub fn new(timeout_ns: u64) -> Self {
        Authority {
            flight: Slot::default(),
            payload: Slot::default(),
            emergency: false,
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
        self.emergency
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

    /// `source` gives `domain` back. `None` if it did not hold it. The safety
    /// source releasing flight authority also ends an emergency stop.
    pub fn release(
        &mut self,
        domain: AuthorityDomain,
        source: CommandSource,
        now_ns: u64,
    ) -> Option<Change> {
        if self.slot(domain).holder != Some(source) {
            return None;
        }
        if domain == AuthorityDomain::Flight {
            self.emergency = false;
        }
        Some(self.transfer(domain, None, AuthorityChange::Released, now_ns))
    }

    /// Emergency stop: safety takes flight authority and keeps it until it releases.
    pub fn emergency(&mut self, now_ns: u64) -> Option<Change> {
        let already = self.emergency && self.flight.holder == Some(CommandSource::Safety);
        self.emergency = true;
        (!already).then(|| {
            self.transfer(
                AuthorityDomain::Flight,
                Some(CommandSource::Safety),
                AuthorityChange::Emergency,
                now_ns,
            )
        })
    }

    /// The link to the autopilot went down: nobody holds authority (an emergency
    /// stop stays in force with safety holding flight authority).
    pub fn link_lost(&mut self, now_ns: u64) -> Vec<Change> {
        let mut changes = Vec::new();
        for domain in [AuthorityDomain::Flight, AuthorityDomain::Payload] {
            let emergency_hold = domain == AuthorityDomain::Flight && self.emergency;
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
        let exempt = domain == AuthorityDomain::Flight && self.emergency;
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
            emergency: u8::from(self.emergency),
            flight_since_ns: self.flight.since_ns,
            payload_since_ns: self.payload.since_ns,
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
    fn emergency_holds_until_safety_releases_and_survives_link_loss() {
        let mut a = Authority::new(5 * S);
        a.act(Flight, ManualRc, S);
        a.act(Payload, Vision, S);
        let c = a.emergency(2 * S).unwrap();
        assert_eq!((c.from, c.to), (Some(ManualRc), Some(Safety)));
        assert_eq!(a.emergency(2 * S), None, "a second stop changes nothing");
        assert!(a.in_emergency());
        assert_eq!(a.state(1).emergency, 1);
        assert_eq!(a.next_deadline(), Some(6 * S), "only payload can time out");
        a.poll(100 * S);
        assert_eq!(a.slot(Flight).holder, Some(Safety));
        let lost = a.link_lost(101 * S);
        assert!(
            lost.is_empty(),
            "payload already timed out, flight held: {lost:?}"
        );
        assert_eq!(a.release(Flight, ManualRc, 102 * S), None);
        a.release(Flight, Safety, 103 * S).unwrap();
        assert!(!a.in_emergency());
        assert_eq!(a.state(1).emergency, 0);
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
