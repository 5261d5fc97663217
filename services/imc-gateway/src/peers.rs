//! Who we talk to (pure, explicit time): peers heard from recently plus the
//! configured static ones, and the periodic schedules for Heartbeat and Announce.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// Where and to whom a message goes: the socket address and the IMC header's
/// destination.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Destination {
    pub addr: SocketAddr,
    /// IMC system address (`dst`); `ADDR_NONE` when unknown.
    pub dst: u16,
    /// IMC entity (`dst_ent`); `ENTITY_ANY` when unknown.
    pub dst_ent: u8,
}

impl Destination {
    /// A destination whose IMC identity is unknown (broadcast address, any entity).
    pub fn anonymous(addr: SocketAddr) -> Self {
        Destination {
            addr,
            dst: imc_proto::ADDR_NONE,
            dst_ent: imc_proto::ENTITY_ANY,
        }
    }
}

/// One peer.
#[derive(Debug, Clone, PartialEq)]
pub struct Peer {
    pub dest: Destination,
    /// `sys_name` of its Announce, once one arrived.
    pub name: Option<String>,
    /// When it last sent a valid message; `None` for a static peer never heard from.
    pub last_seen: Option<Instant>,
    /// From `static_peers`: never expires.
    pub is_static: bool,
}

/// Most dynamic peers remembered; beyond it the one heard from longest ago is
/// forgotten (valid IMC from many source ports must not grow memory without bound).
pub const MAX_PEERS: usize = 256;

/// The peer table.
#[derive(Debug)]
pub struct Peers {
    peers: HashMap<SocketAddr, Peer>,
    timeout: Duration,
}

impl Peers {
    pub fn new(static_peers: &[SocketAddr], timeout: Duration) -> Self {
        let peers = static_peers
            .iter()
            .map(|a| {
                (
                    *a,
                    Peer {
                        dest: Destination::anonymous(*a),
                        name: None,
                        last_seen: None,
                        is_static: true,
                    },
                )
            })
            .collect();
        Peers { peers, timeout }
    }

    /// A valid message from `addr` with header `src`/`src_ent`. Returns a peer that
    /// was forgotten to make room, if any.
    pub fn seen(
        &mut self,
        addr: SocketAddr,
        src: u16,
        src_ent: u8,
        now: Instant,
    ) -> Option<SocketAddr> {
        let dest = Destination {
            addr,
            dst: src,
            dst_ent: src_ent,
        };
        if let Some(p) = self.peers.get_mut(&addr) {
            p.dest = dest;
            p.last_seen = Some(now);
            return None;
        }
        let evicted = if self.dynamic_count() >= MAX_PEERS {
            let oldest = self
                .peers
                .values()
                .filter(|p| !p.is_static)
                .min_by_key(|p| p.last_seen)
                .map(|p| p.dest.addr);
            if let Some(a) = oldest {
                self.peers.remove(&a);
            }
            oldest
        } else {
            None
        };
        self.peers.insert(
            addr,
            Peer {
                dest,
                name: None,
                last_seen: Some(now),
                is_static: false,
            },
        );
        evicted
    }

    /// An Announce from `addr` (after [`Peers::seen`]): remember its name.
    pub fn announced(&mut self, addr: SocketAddr, sys_name: &str) {
        if let Some(p) = self.peers.get_mut(&addr) {
            if p.name.as_deref() != Some(sys_name) {
                tracing::info!(peer = %addr, name = sys_name, "IMC peer announced itself");
                p.name = Some(sys_name.to_string());
            }
        }
    }

    /// Forgets dynamic peers silent for the timeout; returns their addresses.
    pub fn expire(&mut self, now: Instant) -> Vec<SocketAddr> {
        let timeout = self.timeout;
        let gone: Vec<SocketAddr> = self
            .peers
            .values()
            .filter(|p| {
                !p.is_static
                    && p.last_seen
                        .is_none_or(|t| now.saturating_duration_since(t) >= timeout)
            })
            .map(|p| p.dest.addr)
            .collect();
        for a in &gone {
            self.peers.remove(a);
        }
        gone
    }

    /// Everyone who gets a Heartbeat: live dynamic peers and the static ones.
    pub fn heartbeat_targets(&self) -> Vec<Destination> {
        let mut v: Vec<Destination> = self.peers.values().map(|p| p.dest).collect();
        v.sort_by_key(|d| d.addr);
        v
    }

    pub fn get(&self, addr: &SocketAddr) -> Option<&Peer> {
        self.peers.get(addr)
    }

    pub fn len(&self) -> usize {
        self.peers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.peers.is_empty()
    }

    /// When the first dynamic peer falls silent for the timeout (what
    /// [`Peers::expire`] acts on); `None` with no dynamic peer.
    pub fn next_expiry(&self) -> Option<Instant> {
        self.peers
            .values()
            .filter(|p| !p.is_static)
            .map(|p| p.last_seen.map_or(Instant::now(), |t| t + self.timeout))
            .min()
    }

    fn dynamic_count(&self) -> usize {
        self.peers.values().filter(|p| !p.is_static).count()
    }
}

/// A fixed-period schedule: due at start, then every `period`, never bunching up
/// after a stall.
#[derive(Debug, Clone, Copy)]
pub struct Every {
    period: Duration,
    next: Instant,
}

impl Every {
    /// First due at `first`.
    pub fn starting(period: Duration, first: Instant) -> Self {
        Every {
            period,
            next: first,
        }
    }

    /// When it is next due: its stored time, or, if that has passed unseen (nobody
    /// asked [`Every::due`] while there was nothing to do), the next point on the
    /// same period grid after `now`, so an idle wait does not shift its phase.
    pub fn next_due(&self, now: Instant) -> Instant {
        if self.next >= now || self.period.is_zero() {
            return self.next;
        }
        let behind = now.duration_since(self.next).as_nanos();
        let periods = behind / self.period.as_nanos() + 1;
        self.next + self.period * u32::try_from(periods).unwrap_or(u32::MAX)
    }

    /// True (once) when the period has come round.
    pub fn due(&mut self, now: Instant) -> bool {
        if now < self.next {
            return false;
        }
        self.next += self.period;
        if self.next <= now {
            self.next = now + self.period;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn addr(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    #[test]
    fn dynamic_peers_expire_static_ones_stay() {
        let t0 = Instant::now();
        let mut p = Peers::new(&[addr(9)], Duration::from_secs(30));
        assert_eq!(p.heartbeat_targets(), vec![Destination::anonymous(addr(9))]);
        p.seen(addr(1), 0x4001, 3, t0);
        p.seen(addr(9), 0x4009, 0, t0);
        let targets = p.heartbeat_targets();
        assert_eq!(targets.len(), 2);
        assert_eq!(
            targets[0],
            Destination {
                addr: addr(1),
                dst: 0x4001,
                dst_ent: 3
            }
        );
        assert_eq!(targets[1].dst, 0x4009, "a static peer learns its id");
        assert!(p.expire(t0 + Duration::from_secs(29)).is_empty());
        p.seen(addr(2), 0x4002, 0, t0 + Duration::from_secs(20));
        assert_eq!(p.expire(t0 + Duration::from_secs(30)), vec![addr(1)]);
        assert_eq!(p.len(), 2, "addr 2 and the static peer");
        assert_eq!(p.expire(t0 + Duration::from_secs(3600)), vec![addr(2)]);
        assert_eq!(p.heartbeat_targets().len(), 1);
    }

    #[test]
    fn next_due_keeps_the_period_grid_after_an_idle_wait() {
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        let e = Every::starting(s, t0 + s);
        assert_eq!(e.next_due(t0), t0 + s);
        assert_eq!(e.next_due(t0 + s), t0 + s);
        assert_eq!(e.next_due(t0 + s * 3 + s / 2), t0 + s * 4);
    }

    #[test]
    fn next_expiry_is_the_first_dynamic_peer_to_fall_silent() {
        let t0 = Instant::now();
        let timeout = Duration::from_secs(30);
        let mut p = Peers::new(&[addr(9)], timeout);
        assert_eq!(p.next_expiry(), None, "static peers never expire");
        p.seen(addr(1), 0x4001, 0, t0 + Duration::from_secs(5));
        p.seen(addr(2), 0x4002, 0, t0);
        assert_eq!(p.next_expiry(), Some(t0 + timeout));
    }

    #[test]
    fn announce_names_a_peer() {
        let t0 = Instant::now();
        let mut p = Peers::new(&[], Duration::from_secs(30));
        p.announced(addr(1), "ghost");
        assert!(p.get(&addr(1)).is_none(), "unknown peers are not created");
        p.seen(addr(1), 1, 1, t0);
        p.announced(addr(1), "neptus-1");
        assert_eq!(p.get(&addr(1)).unwrap().name.as_deref(), Some("neptus-1"));
    }

    #[test]
    fn the_table_is_bounded_and_forgets_the_oldest() {
        let t0 = Instant::now();
        let mut p = Peers::new(&[addr(1)], Duration::from_secs(30));
        for i in 0..MAX_PEERS as u16 {
            assert_eq!(
                p.seen(
                    addr(100 + i),
                    1,
                    0,
                    t0 + Duration::from_millis(u64::from(i))
                ),
                None
            );
        }
        let evicted = p.seen(addr(50), 1, 0, t0 + Duration::from_secs(1));
        assert_eq!(evicted, Some(addr(100)));
        assert_eq!(p.len(), MAX_PEERS + 1, "plus the static peer");
        assert!(p.get(&addr(1)).is_some());
    }

    #[test]
    fn schedules_fire_once_per_period_without_bunching() {
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        let mut e = Every::starting(s, t0);
        assert!(e.due(t0));
        assert!(!e.due(t0 + Duration::from_millis(999)));
        assert!(e.due(t0 + s));
        // A 10 s stall fires once, then resumes the period.
        assert!(e.due(t0 + 11 * s));
        assert!(!e.due(t0 + 11 * s + Duration::from_millis(500)));
        assert!(e.due(t0 + 12 * s));
    }
}
