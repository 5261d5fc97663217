//! UDP destinations that refuse what is sent to them, and how a sender backs off.
//!
//! A gateway that pushes a stream to configured UDP destinations (autopilot-link's
//! `udpout` ground station at 127.0.0.1:14550, groundcontrol-gateway's pose
//! broadcast) keeps sending whether or not anything listens there. When nothing
//! does, the destination's host answers each datagram with an ICMP port unreachable,
//! and on this project's target class of machine each loopback datagram costs the
//! sender tens of microseconds of CPU (its own send plus the ICMP error, processed in
//! the sender's context): at 50 datagrams a second that was the largest single item
//! of the idle mesh (docs/benchmarks.md, "Then: destinations nobody listens at").
//!
//! [`enable_reports`] asks the kernel to report such errors on an unconnected socket
//! (`IP_RECVERR` / `IPV6_RECVERR`): each lands in the socket's error queue naming the
//! destination, and the next send or receive on the socket fails once with it.
//! [`Refusals`] tracks each destination: one that refused is sent **one datagram a
//! second** (a probe) instead of the stream; when a probe draws no refusal before the
//! next one is due, or a datagram arrives from the destination, the stream resumes.
//! The skipped datagrams are the caller's to count. A destination that starts
//! listening therefore gets its first datagram within a second and the stream
//! within two. Broadcast destinations never refuse (no ICMP error is sent for a
//! broadcast), and a destination whose host is down or filtered (no ICMP error
//! comes back) is sent everything, as before.

use std::io::{self, IoSliceMut};
use std::net::SocketAddr;
use std::os::fd::{AsFd, AsRawFd};
use std::time::Duration;

use nix::errno::Errno;
use nix::sys::socket::{self, sockopt, ControlMessageOwned, MsgFlags, SockaddrStorage};

use crate::clock::monotonic_ns;

/// How often a refusing destination is probed.
pub const PROBE_PERIOD: Duration = Duration::from_secs(1);

/// Asks the kernel to report ICMP errors for datagrams `socket` sends (it is bound
/// to `local`, whose family selects the option).
pub fn enable_reports(socket: &impl AsFd, local: SocketAddr) -> io::Result<()> {
    match local {
        SocketAddr::V4(_) => socket::setsockopt(socket, sockopt::Ipv4RecvErr, &true)?,
        SocketAddr::V6(_) => socket::setsockopt(socket, sockopt::Ipv6RecvErr, &true)?,
    }
    Ok(())
}

/// One report from a socket's error queue: the destination of the datagram that
/// drew it and the error (`ECONNREFUSED` for a port nobody listens at).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Report {
    pub destination: SocketAddr,
    pub error: Errno,
}

/// Reads and empties `socket`'s error queue (never waits). Emptying it also clears
/// the error the next send or receive would otherwise fail with.
pub fn read_reports(socket: &impl AsFd) -> io::Result<Vec<Report>> {
    let fd = socket.as_fd().as_raw_fd();
    let mut reports = Vec::new();
    loop {
        // The queued entry carries the start of the refused datagram; not needed.
        let mut payload = [0u8; 16];
        let mut iov = [IoSliceMut::new(&mut payload)];
        let mut cmsg = nix::cmsg_space!(nix::libc::sock_extended_err, nix::libc::sockaddr_in6);
        let flags = MsgFlags::MSG_ERRQUEUE | MsgFlags::MSG_DONTWAIT;
        match socket::recvmsg::<SockaddrStorage>(fd, &mut iov, Some(&mut cmsg), flags) {
            Ok(msg) => {
                let destination = msg.address.as_ref().and_then(std_addr);
                let mut error = None;
                for c in msg.cmsgs().map_err(io::Error::from)? {
                    match c {
                        ControlMessageOwned::Ipv4RecvErr(e, _)
                        | ControlMessageOwned::Ipv6RecvErr(e, _) => {
                            error = Some(Errno::from_raw(e.ee_errno as i32));
                        }
                        _ => {}
                    }
                }
                if let (Some(destination), Some(error)) = (destination, error) {
                    reports.push(Report { destination, error });
                }
            }
            Err(Errno::EAGAIN) => return Ok(reports),
            Err(Errno::EINTR) => continue,
            Err(e) => return Err(e.into()),
        }
    }
}

fn std_addr(a: &SockaddrStorage) -> Option<SocketAddr> {
    if let Some(v4) = a.as_sockaddr_in() {
        return Some(SocketAddr::V4((*v4).into()));
    }
    a.as_sockaddr_in6().map(|v6| SocketAddr::V6((*v6).into()))
}

/// What to do with a datagram for a destination ([`Refusals::admit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Send it.
    Send,
    /// The destination refused; this one goes as its probe.
    Probe,
    /// The destination refused and its probe is not due: do not send (count it).
    Skip,
}

/// One destination's state. Pure: the clock is an argument.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Gate {
    /// Refused and not heard from since.
    refused: bool,
    /// A refusal was reported since the last probe went out.
    refused_since_probe: bool,
    /// When the next probe is due (`CLOCK_MONOTONIC` ns).
    next_probe_ns: u64,
    /// When the log last said this destination is not listening.
    told_ns: u64,
}

/// While a destination keeps refusing, the log says so again this often.
const REMINDER_NS: u64 = 60_000_000_000;

impl Gate {
    /// A refusal reported at `now_ns`; true if it closes an open gate.
    fn refused(&mut self, now_ns: u64, period_ns: u64) -> bool {
        self.refused_since_probe = true;
        if self.refused {
            return false;
        }
        self.refused = true;
        self.next_probe_ns = now_ns.saturating_add(period_ns);
        self.told_ns = now_ns;
        true
    }

    /// Still refused at `now_ns` and the log has not said so for a minute.
    fn reminder_due(&mut self, now_ns: u64) -> bool {
        if !self.refused || now_ns.saturating_sub(self.told_ns) < REMINDER_NS {
            return false;
        }
        self.told_ns = now_ns;
        true
    }

    /// A datagram at `now_ns`, after the reports so far were read (see
    /// [`Refusals::admit`]); `reopened` tells whether a quiet probe reopened it.
    fn admit(&mut self, now_ns: u64, period_ns: u64) -> (Admit, bool) {
        if !self.refused {
            return (Admit::Send, false);
        }
        if now_ns < self.next_probe_ns {
            return (Admit::Skip, false);
        }
        if !self.refused_since_probe {
            // The last probe drew no refusal for a whole period: it listens.
            *self = Gate::default();
            return (Admit::Send, true);
        }
        self.refused_since_probe = false;
        self.next_probe_ns = now_ns.saturating_add(period_ns);
        (Admit::Probe, false)
    }
}

/// The refusal state of every destination one socket sends to (see the module
/// documentation). Logs each destination's change of state.
#[derive(Debug)]
pub struct Refusals {
    /// Who sends: a log field (e.g. the endpoint's label).
    label: String,
    period_ns: u64,
    /// A short list (one to a few destinations), scanned.
    gates: Vec<(SocketAddr, Gate)>,
}

impl Refusals {
    pub fn new(label: impl Into<String>) -> Refusals {
        Refusals::with_period(label, PROBE_PERIOD)
    }

    /// [`Refusals::new`] with another probe period (tests).
    pub fn with_period(label: impl Into<String>, period: Duration) -> Refusals {
        Refusals {
            label: label.into(),
            period_ns: period.as_nanos().min(u64::MAX as u128) as u64,
            gates: Vec::new(),
        }
    }

    /// Whether to send a datagram to `to` now. When a refusing destination's probe
    /// is due, first reads `socket`'s error queue: the previous probe's refusal may
    /// be waiting there (nothing else was sent since to find it).
    pub fn admit(&mut self, socket: &impl AsFd, to: SocketAddr) -> Admit {
        // The common case, on every datagram of a stream: a listening destination
        // needs neither the clock nor the gate's bookkeeping.
        if !self.is_refusing(to) {
            return Admit::Send;
        }
        self.admit_at(socket, to, monotonic_ns())
    }

    fn admit_at(&mut self, socket: &impl AsFd, to: SocketAddr, now_ns: u64) -> Admit {
        let due = self
            .gate(to)
            .is_some_and(|g| g.refused && now_ns >= g.next_probe_ns);
        if due {
            self.collect_at(socket, now_ns);
        }
        let period_ns = self.period_ns;
        let Some(gate) = self.gate_mut(to) else {
            return Admit::Send;
        };
        let (admit, reopened) = gate.admit(now_ns, period_ns);
        if reopened {
            tracing::info!(sender = %self.label, destination = %to, "udp destination listening again: sending everything");
        }
        admit
    }

    /// A send to `to` failed with `error`. With reports enabled a send fails with
    /// the error an *earlier* datagram drew (that one was not sent); reads the
    /// error queue and returns true if the send should be tried once more (there
    /// were reports and `to` is not refusing).
    pub fn send_failed(&mut self, socket: &impl AsFd, to: SocketAddr, error: &io::Error) -> bool {
        if error.kind() == io::ErrorKind::WouldBlock {
            return false;
        }
        let now_ns = monotonic_ns();
        if self.collect_at(socket, now_ns) == 0 {
            return false;
        }
        !self.gate(to).is_some_and(|g| g.refused)
    }

    /// A receive on the socket failed (the pending error of a report): reads the
    /// error queue. Returns how many reports it held.
    pub fn collect(&mut self, socket: &impl AsFd) -> usize {
        self.collect_at(socket, monotonic_ns())
    }

    /// A datagram came from `from`: if it was refusing, it listens now.
    pub fn heard(&mut self, from: SocketAddr) {
        if let Some(gate) = self.gate_mut(from) {
            if gate.refused {
                *gate = Gate::default();
                tracing::info!(sender = %self.label, destination = %from, "udp destination heard from: sending everything");
            }
        }
    }

    /// When every one of `destinations` is refusing: the time (`CLOCK_MONOTONIC`
    /// ns) the first of them is due a probe, until which a sender has nothing to
    /// send and need not wake. `None` if any of them is not refusing (or there are
    /// none).
    pub fn all_refusing_until(&self, destinations: &[SocketAddr]) -> Option<u64> {
        let mut first: Option<u64> = None;
        for to in destinations {
            let gate = self.gate(*to).filter(|g| g.refused)?;
            first = Some(first.map_or(gate.next_probe_ns, |f| f.min(gate.next_probe_ns)));
        }
        first
    }

    /// Whether `to` is refusing (sent one probe a period).
    pub fn is_refusing(&self, to: SocketAddr) -> bool {
        self.gate(to).is_some_and(|g| g.refused)
    }

    fn collect_at(&mut self, socket: &impl AsFd, now_ns: u64) -> usize {
        match read_reports(socket) {
            Ok(reports) => {
                for r in &reports {
                    self.report_at(*r, now_ns);
                }
                reports.len()
            }
            Err(e) => {
                tracing::debug!(sender = %self.label, error = %e, "reading the socket's error queue failed");
                0
            }
        }
    }

    /// Applies one report at `now_ns`.
    fn report_at(&mut self, report: Report, now_ns: u64) {
        if report.error != Errno::ECONNREFUSED {
            tracing::debug!(sender = %self.label, destination = %report.destination, error = %report.error, "udp send error reported");
            return;
        }
        let period_ns = self.period_ns;
        let (closed, remind) = match self.gate_mut(report.destination) {
            Some(gate) => {
                let closed = gate.refused(now_ns, period_ns);
                (closed, !closed && gate.reminder_due(now_ns))
            }
            None => {
                let mut gate = Gate::default();
                gate.refused(now_ns, period_ns);
                self.gates.push((report.destination, gate));
                (true, false)
            }
        };
        // A ground station or pose listener that is simply not there is normal
        // (INFO, reminded once a minute), not a fault to warn about.
        if closed {
            tracing::info!(
                sender = %self.label,
                destination = %report.destination,
                probe_every_s = self.period_ns as f64 / 1e9,
                "udp destination not listening (ICMP port unreachable): one datagram a second until it is"
            );
        } else if remind {
            tracing::info!(
                sender = %self.label,
                destination = %report.destination,
                "udp destination still not listening"
            );
        }
    }

    fn gate(&self, to: SocketAddr) -> Option<&Gate> {
        self.gates.iter().find(|(a, _)| *a == to).map(|(_, g)| g)
    }

    fn gate_mut(&mut self, to: SocketAddr) -> Option<&mut Gate> {
        self.gates
            .iter_mut()
            .find(|(a, _)| *a == to)
            .map(|(_, g)| g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::UdpSocket;

    const S: u64 = 1_000_000_000;

    #[test]
    fn a_refusing_destination_is_reminded_once_a_minute() {
        let mut g = Gate::default();
        assert!(g.refused(10, S));
        assert!(!g.reminder_due(30 * S), "not before a minute");
        assert!(!g.refused(59 * S, S));
        assert!(g.reminder_due(61 * S));
        assert!(!g.reminder_due(62 * S), "once, then a minute again");
        assert!(g.reminder_due(122 * S));
    }

    #[test]
    fn a_refused_gate_skips_until_its_probe_and_reopens_after_a_quiet_probe() {
        let mut g = Gate::default();
        assert_eq!(g.admit(0, S), (Admit::Send, false));
        assert!(g.refused(10, S));
        assert!(!g.refused(20, S), "a second report does not close it again");
        assert_eq!(g.admit(30, S), (Admit::Skip, false));
        assert_eq!(g.admit(S + 9, S), (Admit::Skip, false));
        // The first probe: a refusal came since the gate closed.
        assert_eq!(g.admit(S + 10, S), (Admit::Probe, false));
        assert_eq!(g.admit(S + 11, S), (Admit::Skip, false));
        // That probe was refused too: probe again.
        g.refused(S + 12, S);
        assert_eq!(g.admit(2 * S + 10, S), (Admit::Probe, false));
        // This one was not: the next datagram after a whole period goes, and all after it.
        assert_eq!(g.admit(3 * S + 9, S), (Admit::Skip, false));
        assert_eq!(g.admit(3 * S + 10, S), (Admit::Send, true));
        assert_eq!(g.admit(3 * S + 11, S), (Admit::Send, false));
    }

    #[test]
    fn a_sender_may_sleep_only_while_every_destination_refuses() {
        let a: SocketAddr = "127.0.0.1:1".parse().unwrap();
        let b: SocketAddr = "127.0.0.1:2".parse().unwrap();
        let refused = |to| Report {
            destination: to,
            error: Errno::ECONNREFUSED,
        };
        let mut r = Refusals::with_period("test", Duration::from_nanos(S));
        assert_eq!(r.all_refusing_until(&[]), None);
        assert_eq!(r.all_refusing_until(&[a, b]), None);
        r.report_at(refused(a), 100);
        assert_eq!(r.all_refusing_until(&[a, b]), None, "b still listens");
        assert_eq!(r.all_refusing_until(&[a]), Some(S + 100));
        r.report_at(refused(b), 300);
        assert_eq!(
            r.all_refusing_until(&[a, b]),
            Some(S + 100),
            "the first probe due"
        );
        r.heard(a);
        assert_eq!(r.all_refusing_until(&[a, b]), None);
        // Other errors (host unreachable, message too long) close no gate.
        r.report_at(
            Report {
                destination: a,
                error: Errno::EHOSTUNREACH,
            },
            400,
        );
        assert!(!r.is_refusing(a));
    }

    /// A loopback port with nothing bound to it: bind, note the port, close.
    fn closed_port() -> SocketAddr {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        s.local_addr().unwrap()
    }

    fn sender() -> UdpSocket {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        enable_reports(&s, s.local_addr().unwrap()).unwrap();
        s
    }

    /// Waits (at most 2 s) until `socket` has an error pending. Loopback ICMP is
    /// normally processed before `send_to` returns, but under load the kernel may
    /// defer it to ksoftirqd.
    fn wait_for_error(socket: &UdpSocket) {
        use nix::sys::epoll::{Epoll, EpollCreateFlags, EpollEvent, EpollFlags};
        let epoll = Epoll::new(EpollCreateFlags::empty()).unwrap();
        // No interest: only EPOLLERR (and EPOLLHUP) are reported.
        epoll
            .add(socket, EpollEvent::new(EpollFlags::empty(), 0))
            .unwrap();
        let mut events = [EpollEvent::empty()];
        let n = epoll.wait(&mut events, 2000u16).unwrap();
        assert_eq!(n, 1, "no error reported within 2 s");
    }

    fn reports_within(socket: &UdpSocket) -> Vec<Report> {
        wait_for_error(socket);
        read_reports(socket).unwrap()
    }

    #[test]
    fn the_kernel_reports_a_datagram_to_a_closed_port_naming_its_destination() {
        let (s, closed) = (sender(), closed_port());
        let listener = UdpSocket::bind("127.0.0.1:0").unwrap();
        let open = listener.local_addr().unwrap();
        s.send_to(b"x", open).unwrap();
        s.send_to(b"y", closed).unwrap();
        let reports = reports_within(&s);
        assert_eq!(
            reports,
            vec![Report {
                destination: closed,
                error: Errno::ECONNREFUSED
            }]
        );
        // Emptying the queue cleared the pending error: the next send goes.
        s.send_to(b"z", open).unwrap();
        let mut buf = [0u8; 4];
        listener
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        assert_eq!(listener.recv(&mut buf).unwrap(), 1);
        assert_eq!(listener.recv(&mut buf).unwrap(), 1);
        assert_eq!(&buf[..1], b"z");
    }

    #[test]
    fn a_closed_port_gets_one_probe_a_period_and_the_stream_when_it_opens() {
        let s = sender();
        let closed = closed_port();
        // Long enough that a stalled test thread does not reach a probe early.
        let period = Duration::from_millis(500);
        let mut r = Refusals::with_period("test", period);
        // The first datagram goes; its refusal fails the next send, which reads it.
        assert_eq!(r.admit(&s, closed), Admit::Send);
        s.send_to(b"1", closed).unwrap();
        assert_eq!(reports_within(&s).len(), 1, "the port refused");
        // (Reading the queue directly consumed the report; feed it as a send would.)
        s.send_to(b"2", closed).unwrap();
        wait_for_error(&s);
        let err = s
            .send_to(b"3", closed)
            .expect_err("the refusal of 2 fails the next send");
        assert!(
            !r.send_failed(&s, closed, &err),
            "no retry to a refusing port"
        );
        assert!(r.is_refusing(closed));
        // Until the probe is due nothing goes.
        for _ in 0..50 {
            assert_eq!(r.admit(&s, closed), Admit::Skip);
        }
        std::thread::sleep(period);
        assert_eq!(r.admit(&s, closed), Admit::Probe);
        s.send_to(b"probe", closed).unwrap();
        wait_for_error(&s);
        // Still closed at the next probe: its refusal is read from the queue there.
        std::thread::sleep(period);
        assert_eq!(r.admit(&s, closed), Admit::Probe);
        // Now something listens there; the probe draws no refusal.
        let listener = UdpSocket::bind(closed).unwrap();
        s.send_to(b"probe", closed).unwrap();
        std::thread::sleep(period);
        assert_eq!(r.admit(&s, closed), Admit::Send, "a quiet probe reopens it");
        assert!(!r.is_refusing(closed));
        s.send_to(b"data", closed).unwrap();
        let mut buf = [0u8; 8];
        listener
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        assert_eq!(listener.recv(&mut buf).unwrap(), 5);
        assert_eq!(listener.recv(&mut buf).unwrap(), 4);
    }

    #[test]
    fn a_refusal_reported_on_another_destinations_send_is_retried_and_hearing_reopens() {
        let s = sender();
        let (closed, listener) = (closed_port(), UdpSocket::bind("127.0.0.1:0").unwrap());
        let open = listener.local_addr().unwrap();
        let mut r = Refusals::new("test");
        s.send_to(b"to closed", closed).unwrap();
        wait_for_error(&s);
        // The pending refusal fails this send to the open destination…
        let err = s.send_to(b"to open", open).expect_err("pending refusal");
        // …which is retried, and the closed one now skips.
        assert!(r.send_failed(&s, open, &err));
        s.send_to(b"to open", open).unwrap();
        assert_eq!(r.admit(&s, closed), Admit::Skip);
        assert_eq!(r.admit(&s, open), Admit::Send);
        r.heard(closed);
        assert_eq!(r.admit(&s, closed), Admit::Send, "heard from: listens");
        let mut buf = [0u8; 16];
        listener
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        assert_eq!(listener.recv(&mut buf).unwrap(), 7);
    }
}
