//! Small-sample transport benchmark (issue 10, item 1 and the low-latency option): a
//! `VehicleState` between this process and a child process through the skymesh bus
//! (iceoryx2 via `skymesh_runtime`) vs loopback UDP carrying the same bytes, same
//! run, interleaved.
//!
//! ```text
//! cargo run --release -p skymesh-e2e --bin samples-bench [-- SCALE]
//! ```
//!
//! **One way**, at 100 Hz (500 messages), 1 kHz (2,000) and back to back (2,000),
//! `SCALE` multiplying the counts, five receivers per rate, in this order:
//! - `iox raw`: raw iceoryx2 ports, none of skymesh's code: thread-safe
//!   publish-subscribe and its socket event, `send_copy` + `notify`, the receiver
//!   blocked in the listener's wait — what iceoryx2's own blocking wake-up costs;
//! - `udp blk`: `std::net::UdpSocket::recv`, blocking;
//! - `udp blk2`: a second `udp blk` receiver, the comparison's noise floor: with
//!   `--interleave`, the row `u÷i udp2` is UDP against itself, and how far its
//!   ratios stray from 1 is how far the host alone moves a ratio in that run;
//! - `iox tok`: `Subscriber::recv` awaited in a tokio current-thread runtime (event
//!   wake-up through epoll: how the services receive);
//! - `udp tok`: `tokio::net::UdpSocket::recv` in the same kind of runtime.
//!
//! `--interleave` runs a rate's receivers at once, the sender taking turns message by
//! message, so whatever the host does falls on all of them alike (back to back stays
//! one receiver at a time).
//!
//! `SAMPLES_BENCH_STAMPS=FILE` appends `receiver-pid k send-stamp receive-time` (ns,
//! `CLOCK_MONOTONIC`) of every message to FILE, to join with a kernel trace taken
//! with the same clock (`perf record -k CLOCK_MONOTONIC`; see docs/benchmarks.md).
//!
//! Latency = the receiver's `CLOCK_MONOTONIC` when it holds the sample − the send
//! stamp carried in it (the bus stamps `header.stamp_ns` just before sending; the
//! UDP sender writes the same clock just before `send`). CPU per message is
//! `CLOCK_PROCESS_CPUTIME_ID` (user + system) over the counted part of each phase,
//! on each side; with `--interleave` the sender's is each send's own (the thread's
//! CPU clock around it, `SendSlot`), without the pacing sleep, and `rx+tx` is the
//! message's whole cost. The first [`WARMUP`] messages of each phase are not counted. The bus
//! topic holds a whole phase (nothing overwritten), so back to back both transports
//! queue; that row measures queueing and the per-message cost, not wake-ups.
//!
//! **Ping-pong**: the parent sends a sample, the child sends it straight back, 2,000 ×
//! `SCALE` round trips back to back; one-way latency = round trip / 2. `busy`: both
//! sides poll shared memory with `try_recv` and never block (the floor of this
//! machine); `block`: both sides await `Subscriber::recv` in a tokio current-thread
//! runtime (the services' receive); `udp`: blocking sockets. CPU is per round trip
//! on each side.

use std::io::{BufReader, Write};
use std::net::UdpSocket;
use std::process::{Child, ChildStdout};
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use skymesh_e2e::transport_bench::{
    bench_state, datagram_fields, die_with_parent, finish_child, percentiles, process_cpu_ns,
    read_line, recv_until_idle, retry_interrupted, send_loop, spawn_child, stamp_datagram,
    DomainGuard, Rate, SendSlot, Tally, DATAGRAM_LEN,
};
use skymesh_ipc_types::{ServiceId, Topic, TopicQos, VehicleState};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, Domain, Stats};

/// Messages at the start of each phase not counted (first wake-ups, page faults).
const WARMUP: usize = 50;
/// Vehicle id written into the benchmark's samples.
const VEHICLE: u8 = 201;
/// The receiver stops when nothing arrived for this long (the last message was lost).
const IDLE_END: Duration = Duration::from_secs(2);
/// Bytes per UDP datagram: exactly a `VehicleState`.
const LEN: usize = DATAGRAM_LEN;

/// How a one-way receiver waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Via {
    UdpBlocking,
    /// A second `udp-blk` receiver, for the comparison's noise floor: `udp-blk` ÷
    /// `udp-blk2` is the same mechanism against itself, so how far its ratios stray
    /// from 1 in a run is how far host noise alone moves a ratio.
    UdpBlockingAgain,
    IoxTokio,
    UdpTokio,
    /// Raw iceoryx2, none of skymesh's code: the thread-safe publish-subscribe
    /// service and its socket event, `send_copy` + `notify`, the receiver blocked in
    /// the event listener's wait: what iceoryx2's own blocking wake-up costs.
    IoxRaw,
}

impl Via {
    const ALL: [Via; 5] = [
        Via::IoxRaw,
        Via::UdpBlocking,
        Via::UdpBlockingAgain,
        Via::IoxTokio,
        Via::UdpTokio,
    ];

    fn arg(self) -> &'static str {
        match self {
            Via::UdpBlocking => "udp-blk",
            Via::UdpBlockingAgain => "udp-blk2",
            Via::IoxTokio => "iox-tok",
            Via::UdpTokio => "udp-tok",
            Via::IoxRaw => "iox-raw",
        }
    }

    fn parse(s: &str) -> anyhow::Result<Via> {
        Via::ALL
            .into_iter()
            .find(|v| v.arg() == s)
            .ok_or_else(|| anyhow::anyhow!("unknown receiver `{s}`"))
    }

    fn is_iox(self) -> bool {
        self == Via::IoxTokio
    }
}

/// How the ping-pong partners wait.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pong {
    Busy,
    Block,
    Udp,
}

impl Pong {
    const ALL: [Pong; 3] = [Pong::Busy, Pong::Block, Pong::Udp];

    fn arg(self) -> &'static str {
        match self {
            Pong::Busy => "busy",
            Pong::Block => "block",
            Pong::Udp => "udp",
        }
    }

    fn parse(s: &str) -> anyhow::Result<Pong> {
        Pong::ALL
            .into_iter()
            .find(|v| v.arg() == s)
            .ok_or_else(|| anyhow::anyhow!("unknown ping-pong mode `{s}`"))
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("--sub") => {
            die_with_parent()?;
            receiver(Via::parse(&args[2])?, &args[3], args[4].parse()?)
        }
        Some("--pong") => {
            die_with_parent()?;
            pong_child(Pong::parse(&args[2])?, &args[3], args[4].parse()?)
        }
        _ => {
            // [SCALE] [--only NAME,NAME...] (receiver / ping-pong mode names; for profiling)
            let mut scale = 1;
            let mut only: Option<Vec<String>> = None;
            let mut interleave = false;
            let mut it = args.iter().skip(1);
            while let Some(a) = it.next() {
                if a == "-h" || a == "--help" {
                    println!(
                        "usage: samples-bench [SCALE] [--only NAME,...] [--interleave]\n\
                         iceoryx2 (skymesh bus) vs loopback UDP, one way at 100 Hz, 1 kHz and\n\
                         back to back, then ping-pong; SCALE multiplies the message counts;\n\
                         --only runs the named receivers / ping-pong modes (e.g. iox-tok,udp-tok);\n\
                         --interleave runs a rate's receivers at once, their messages taking\n\
                         turns (the host's noise falls on all alike; back to back stays apart)"
                    );
                    return Ok(());
                }
                if a == "--interleave" {
                    interleave = true;
                } else if a == "--only" {
                    let list = it
                        .next()
                        .ok_or_else(|| anyhow::anyhow!("--only needs names"))?;
                    only = Some(list.split(',').map(str::to_string).collect());
                } else {
                    scale = a.parse()?;
                }
            }
            anyhow::ensure!(scale >= 1, "SCALE must be at least 1");
            let wanted =
                move |name: &str| only.as_ref().is_none_or(|o| o.iter().any(|n| n == name));
            driver(scale, &wanted, interleave)
        }
    }
}

/// What one phase measured.
struct Phase {
    /// Latencies of the counted messages, ns.
    lat: Vec<u64>,
    /// Messages the receiver got (warm-up included).
    got: usize,
    sent: usize,
    /// Receiver CPU per counted message, ns.
    rx_cpu: f64,
    /// Sender CPU per counted message, ns.
    tx_cpu: f64,
}

/// A bench topic whose subscriber buffer holds a whole phase (nothing overwritten).
fn bench_topic(name: &str, n: usize) -> Topic {
    Topic {
        name: format!("skymesh/bench/{VEHICLE}/{name}"),
        qos: TopicQos {
            max_publishers: 1,
            max_subscribers: 1,
            max_nodes: 4,
            history: 0,
            buffer: n.max(1),
        },
    }
}

fn driver(scale: usize, wanted: &dyn Fn(&str) -> bool, interleave: bool) -> anyhow::Result<()> {
    let name = format!("sb{}", std::process::id());
    let domain = DomainGuard(Domain::load(&name, None)?);
    let _raw = DomainGuard(raw_domain(&name)?);
    let plan = [
        (Rate::Hz(100.0), 500 * scale),
        (Rate::Hz(1000.0), 2000 * scale),
        (Rate::BackToBack, 2000 * scale),
    ];
    println!(
        "samples-bench: VehicleState ({LEN} bytes) one way parent → child process; domain \
         {name}; first {WARMUP} of each phase not counted; latency µs, CPU µs per message"
    );
    println!(
        "{:>7} | {:>7} {:>11} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "rate", "via", "got", "p50", "p99", "p999", "rx cpu", "tx cpu", "rx+tx"
    );
    for (rate, n) in plan {
        let vias: Vec<Via> = Via::ALL.into_iter().filter(|v| wanted(v.arg())).collect();
        let measured = match rate {
            Rate::Hz(hz) if interleave => one_way_interleaved(&domain.0, &vias, hz, n)?,
            _ => {
                let mut all = Vec::with_capacity(vias.len());
                for via in &vias {
                    all.push(one_way(&domain.0, *via, rate, n)?);
                }
                all
            }
        };
        let mut phases = Vec::new();
        for (via, ph) in vias.into_iter().zip(measured) {
            let p = percentiles(&ph.lat);
            println!(
                "{:>7} | {:>7} {:>11} {:>8.1} {:>8.1} {:>8.1} {:>8.2} {:>8.2} {:>8.2}",
                rate.label(),
                via.arg(),
                format!("{}/{}", ph.got, ph.sent),
                p[0] / 1e3,
                p[1] / 1e3,
                p[2] / 1e3,
                ph.rx_cpu / 1e3,
                ph.tx_cpu / 1e3,
                (ph.rx_cpu + ph.tx_cpu) / 1e3,
            );
            phases.push((via, p, ph));
        }
        for (label, udp, iox) in [
            ("raw", Via::UdpBlocking, Via::IoxRaw),
            ("tok", Via::UdpTokio, Via::IoxTokio),
            ("udp2", Via::UdpBlocking, Via::UdpBlockingAgain),
        ] {
            let find = |v: Via| phases.iter().find(|(w, _, _)| *w == v);
            let (Some((_, pu, u)), Some((_, pi, i))) = (find(udp), find(iox)) else {
                continue;
            };
            println!(
                "{:>7} | {:>7} {:>11} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
                rate.label(),
                format!("u÷i {label}"),
                "",
                pu[0] / pi[0],
                pu[1] / pi[1],
                pu[2] / pi[2],
                u.rx_cpu / i.rx_cpu,
                u.tx_cpu / i.tx_cpu,
                (u.rx_cpu + u.tx_cpu) / (i.rx_cpu + i.tx_cpu),
            );
        }
    }
    let n = 2000 * scale;
    println!(
        "ping-pong: {n} round trips back to back, one way = round trip / 2 (µs); \
         CPU µs per round trip"
    );
    println!(
        "{:>7} | {:>8} {:>8} {:>8} {:>9} {:>8} {:>8}",
        "mode", "p50", "p99", "p999", "p99÷busy", "ping cpu", "pong cpu"
    );
    let mut floor = f64::NAN;
    for mode in Pong::ALL {
        if !wanted(mode.arg()) {
            continue;
        }
        let (lat, ping_cpu, pong_cpu) = ping_pong(&domain.0, mode, n)?;
        let p = percentiles(&lat);
        if mode == Pong::Busy {
            floor = p[1];
        }
        println!(
            "{:>7} | {:>8.2} {:>8.2} {:>8.2} {:>9.2} {:>8.2} {:>8.2}",
            mode.arg(),
            p[0] / 1e3,
            p[1] / 1e3,
            p[2] / 1e3,
            p[1] / floor,
            ping_cpu / 1e3,
            pong_cpu / 1e3,
        );
    }
    let left = domain.0.leftover_files();
    drop(domain);
    println!("removed {} leftover shared-memory files", left.len());
    Ok(())
}

/// Reads the receiver's report (`transport_bench::Tally`'s).
fn finish(
    child: Child,
    out: BufReader<ChildStdout>,
    sent: usize,
    tx_cpu: f64,
) -> anyhow::Result<Phase> {
    let rx = finish_child(child, out)?;
    Ok(Phase {
        lat: rx.latencies(),
        got: rx.got,
        sent,
        rx_cpu: rx.cpu_per_msg(),
        tx_cpu,
    })
}

/// What the receiver accumulates, the same for every transport: the shared
/// [`Tally`], and every message's stamps when `SAMPLES_BENCH_STAMPS` names a file.
struct Received {
    tally: Tally,
    n: usize,
    /// `(k, send stamp, receive time)` of every message, kept when
    /// `SAMPLES_BENCH_STAMPS` names a file (to join with a kernel trace).
    stamps: Option<Vec<(usize, u64, u64)>>,
}

impl Received {
    fn new(n: usize) -> Received {
        Received {
            tally: Tally::new(n, WARMUP),
            n,
            stamps: std::env::var_os("SAMPLES_BENCH_STAMPS").map(|_| Vec::with_capacity(n)),
        }
    }

    /// Records message `k` sent at `t0`, received at `t1`; true after the last one.
    fn add(&mut self, k: usize, t0: u64, t1: u64) -> bool {
        if let Some(stamps) = &mut self.stamps {
            stamps.push((k, t0, t1));
        }
        self.tally.add(k, t0, t1);
        k + 1 >= self.n
    }

    fn report(self) -> anyhow::Result<()> {
        if let (Some(stamps), Some(path)) = (&self.stamps, std::env::var_os("SAMPLES_BENCH_STAMPS"))
        {
            // Appended: one file collects every phase, each line `pid k t0 t1`.
            // Receivers of an interleaved phase end together, so the lines are
            // written in one `write` (an unbuffered `writeln!` writes each piece
            // on its own, and two processes' pieces interleave).
            let pid = std::process::id();
            let mut lines = String::with_capacity(stamps.len() * 48);
            for (k, t0, t1) in stamps {
                lines.push_str(&format!("{pid} {k} {t0} {t1}\n"));
            }
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)?
                .write_all(lines.as_bytes())?;
        }
        self.tally.report()
    }
}

fn raw_err(e: impl std::fmt::Debug) -> anyhow::Error {
    anyhow::anyhow!("iceoryx2: {e:?}")
}

/// The domain of `iox-raw`'s services: their own, so that neither they nor the
/// bus ever list or open the other's files.
fn raw_domain(domain: &str) -> anyhow::Result<Domain> {
    Ok(Domain::load(&format!("{domain}raw"), None)?)
}

/// `iox-raw`'s services: publish-subscribe and event on the thread-safe flavour,
/// laid out as the bus lays out a topic's.
struct RawPorts {
    pubsub: iceoryx2::service::port_factory::publish_subscribe::PortFactory<
        ipc_threadsafe::Service,
        VehicleState,
        (),
    >,
    event: iceoryx2::service::port_factory::event::PortFactory<ipc_threadsafe::Service>,
    _node: Node<ipc_threadsafe::Service>,
}

impl RawPorts {
    /// `via`'s services.
    fn open(domain: &str, via: Via, n: usize) -> anyhow::Result<RawPorts> {
        let domain = raw_domain(domain)?;
        let name: ServiceName = format!("bench/{}", via.arg())
            .as_str()
            .try_into()
            .map_err(raw_err)?;
        let node = NodeBuilder::new()
            .config(&domain.config)
            .create::<ipc_threadsafe::Service>()
            .map_err(raw_err)?;
        let pubsub = node
            .service_builder(&name)
            .publish_subscribe::<VehicleState>()
            .max_publishers(1)
            .max_subscribers(1)
            .history_size(0)
            .subscriber_max_buffer_size(n.max(1))
            .open_or_create()
            .map_err(raw_err)?;
        let event = node
            .service_builder(&name)
            .event()
            .event_id_max_value(0)
            .open_or_create()
            .map_err(raw_err)?;
        Ok(RawPorts {
            pubsub,
            event,
            _node: node,
        })
    }
}

/// Starts a shared-memory receiver child and waits until it is subscribed.
fn start_shm_receiver(
    domain: &Domain,
    via: Via,
    n: usize,
) -> anyhow::Result<(Child, BufReader<ChildStdout>)> {
    let (child, mut out) = spawn_child(&[
        "--sub".into(),
        via.arg().into(),
        domain.name.clone(),
        n.to_string(),
    ])?;
    let ready = read_line(&mut out)?;
    anyhow::ensure!(ready == "ready", "receiver said `{ready}`");
    std::thread::sleep(Duration::from_millis(100));
    Ok((child, out))
}

/// The sending end of one receiver child's phase.
enum Sender {
    /// The skymesh bus: a fresh bus and publisher per phase, so no phase inherits
    /// another's samples.
    Bus {
        publ: Box<skymesh_runtime::Publisher<VehicleState>>,
        state: VehicleState,
        _bus: Bus,
    },
    /// Raw iceoryx2 (`iox-raw`).
    Raw(Box<RawSender>),
    Udp {
        sock: UdpSocket,
        buf: [u8; LEN],
    },
}

/// `iox-raw`'s sending end.
struct RawSender {
    publ: iceoryx2::port::publisher::Publisher<ipc_threadsafe::Service, VehicleState, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc_threadsafe::Service>,
    state: VehicleState,
    _ports: RawPorts,
}

/// One receiver child and the sender that feeds it.
struct Link {
    child: Child,
    out: BufReader<ChildStdout>,
    sender: Sender,
}

impl Link {
    /// Starts `via`'s receiver child for `n` messages and opens its sender.
    fn start(domain: &Domain, via: Via, n: usize) -> anyhow::Result<Link> {
        if via == Via::IoxRaw {
            let ports = RawPorts::open(&domain.name, via, n)?;
            let publ = ports.pubsub.publisher_builder().create().map_err(raw_err)?;
            let notifier = ports.event.notifier_builder().create().map_err(raw_err)?;
            let (child, out) = start_shm_receiver(domain, via, n)?;
            let sender = Sender::Raw(Box::new(RawSender {
                publ,
                notifier,
                state: bench_state(VEHICLE),
                _ports: ports,
            }));
            return Ok(Link { child, out, sender });
        }
        if via.is_iox() {
            let bus = Bus::open(domain, "bench-state-pub", ServiceId::Tool, 0, Stats::new())?;
            let publ = Box::new(bus.publisher::<VehicleState>(&one_way_topic(via, n))?);
            let (child, out) = start_shm_receiver(domain, via, n)?;
            let sender = Sender::Bus {
                publ,
                state: bench_state(VEHICLE),
                _bus: bus,
            };
            return Ok(Link { child, out, sender });
        }
        let (child, mut out) =
            spawn_child(&["--sub".into(), via.arg().into(), "-".into(), n.to_string()])?;
        let ready = read_line(&mut out)?;
        let port: u16 = match ready.strip_prefix("ready ") {
            Some(p) => p.parse()?,
            None => anyhow::bail!("receiver said `{ready}`"),
        };
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        sock.connect(("127.0.0.1", port))?;
        std::thread::sleep(Duration::from_millis(100));
        let sender = Sender::Udp {
            sock,
            buf: [0u8; LEN],
        };
        Ok(Link { child, out, sender })
    }

    /// Sends message `k` (0-based; sequence `k + 1`).
    fn send(&mut self, k: usize) -> anyhow::Result<()> {
        match &mut self.sender {
            Sender::Bus { publ, state, .. } => {
                state.time_boot_ms = k as u32;
                // The bus stamps `header.seq` (k + 1) and `header.stamp_ns` as it sends.
                publ.publish(*state)?;
            }
            Sender::Raw(_) => self.send_raw(k, k as u64 + 1)?,
            Sender::Udp { sock, buf } => {
                stamp_datagram(buf, VEHICLE, k);
                let sent = sock.send(buf)?;
                anyhow::ensure!(sent == LEN, "sent {sent} of {LEN} bytes");
            }
        }
        Ok(())
    }

    fn send_raw(&mut self, k: usize, seq: u64) -> anyhow::Result<()> {
        if let Sender::Raw(raw) = &mut self.sender {
            raw.state.time_boot_ms = k as u32;
            raw.state.header.seq = seq;
            raw.state.header.stamp_ns = monotonic_ns();
            raw.publ.send_copy(raw.state).map_err(raw_err)?;
            raw.notifier.notify().map_err(raw_err)?;
        }
        Ok(())
    }

    /// Ends the phase after `n` messages and reads the receiver's report.
    fn finish(mut self, n: usize, tx_cpu: f64) -> anyhow::Result<Phase> {
        // Sequence 0 ends an `iox-raw` receiver still waiting for a lost sample (it
        // has no idle timeout).
        self.send_raw(n, 0)?;
        finish(self.child, self.out, n, tx_cpu)
    }
}

/// `via`'s one-way topic: one per receiver kind, so interleaved phases do not share.
fn one_way_topic(via: Via, n: usize) -> Topic {
    bench_topic(&format!("one_way_{}", via.arg().replace('-', "_")), n)
}

/// One receiver alone for a phase.
fn one_way(domain: &Domain, via: Via, rate: Rate, n: usize) -> anyhow::Result<Phase> {
    let mut link = Link::start(domain, via, n)?;
    let tx_cpu = send_loop(rate, n, WARMUP, |k| link.send(k))?;
    link.finish(n, tx_cpu)
}

/// All of `vias` in one phase, message by message: each receiver gets `n` messages
/// at `hz`, the senders take turns (receiver `i` of `m` at offsets `i / (m · hz)`),
/// so whatever the host does during the phase falls on every receiver alike. The
/// sender's CPU is each send's own ([`SendSlot`]: the thread's CPU clock around it),
/// without the pacing sleep's wake-up that a whole phase's CPU includes.
fn one_way_interleaved(
    domain: &Domain,
    vias: &[Via],
    hz: f64,
    n: usize,
) -> anyhow::Result<Vec<Phase>> {
    let mut links = Vec::with_capacity(vias.len());
    for via in vias {
        links.push(Link::start(domain, *via, n)?);
    }
    let m = links.len();
    let mut slots = vec![SendSlot::default(); m];
    send_loop(Rate::Hz(hz * m as f64), n * m, WARMUP * m, |k| {
        let (i, j) = (k % m, k / m);
        slots[i].time(j >= WARMUP, || links[i].send(j))
    })?;
    links
        .into_iter()
        .zip(slots)
        .map(|(link, slot)| link.finish(n, slot.per_msg()))
        .collect()
}

fn receiver(via: Via, domain: &str, n: usize) -> anyhow::Result<()> {
    let mut tally = Received::new(n);
    let iox_sample = |tally: &mut Received, s: VehicleState| -> anyhow::Result<bool> {
        let t1 = monotonic_ns();
        anyhow::ensure!(
            s.vehicle_id == VEHICLE,
            "sample of vehicle {}",
            s.vehicle_id
        );
        let k = s.header.seq.saturating_sub(1) as usize;
        Ok(tally.add(k, s.header.stamp_ns, t1))
    };
    let udp_sample = |tally: &mut Received, buf: &[u8], len: usize| -> anyhow::Result<bool> {
        let t1 = monotonic_ns();
        let (seq, t0) = datagram_fields(buf, len, VEHICLE)?;
        Ok(tally.add(seq.saturating_sub(1) as usize, t0, t1))
    };
    let rt = || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
    };
    match via {
        Via::IoxTokio => {
            let domain = Domain::load(domain, None)?;
            let bus = Bus::open(&domain, "bench-state-sub", ServiceId::Tool, 0, Stats::new())?;
            let mut sub = bus.subscriber::<VehicleState>(&one_way_topic(via, n))?;
            println!("ready");
            rt()?.block_on(async {
                while let Some(s) = sub.recv_timeout(IDLE_END).await? {
                    if iox_sample(&mut tally, s)? {
                        break;
                    }
                }
                anyhow::Ok(())
            })?;
        }
        Via::IoxRaw => {
            let raw = RawPorts::open(domain, via, n)?;
            let sub = raw.pubsub.subscriber_builder().create().map_err(raw_err)?;
            let listener = raw.event.listener_builder().create().map_err(raw_err)?;
            println!("ready");
            // Look, and block only when nothing is pending.
            'phase: loop {
                while let Some(smp) = sub.receive().map_err(raw_err)? {
                    let s: VehicleState = *smp.payload();
                    drop(smp);
                    if s.header.seq == 0 || iox_sample(&mut tally, s)? {
                        break 'phase;
                    }
                }
                listener.blocking_wait(|_| {}).map_err(raw_err)?;
            }
        }
        Via::UdpBlocking | Via::UdpBlockingAgain => {
            let sock = UdpSocket::bind("127.0.0.1:0")?;
            sock.set_read_timeout(Some(IDLE_END))?;
            println!("ready {}", sock.local_addr()?.port());
            let mut buf = [0u8; LEN + 1];
            while let Some(len) = recv_until_idle(&sock, &mut buf)? {
                if udp_sample(&mut tally, &buf, len)? {
                    break;
                }
            }
        }
        Via::UdpTokio => {
            let rt = rt()?;
            rt.block_on(async {
                let sock = tokio::net::UdpSocket::bind("127.0.0.1:0").await?;
                println!("ready {}", sock.local_addr()?.port());
                let mut buf = [0u8; LEN + 1];
                while let Ok(r) = tokio::time::timeout(IDLE_END, sock.recv(&mut buf)).await {
                    if udp_sample(&mut tally, &buf, r?)? {
                        break;
                    }
                }
                anyhow::Ok(())
            })?;
        }
    }
    tally.report()
}

/// Receives the next sample the way `mode` waits: `busy` polls with `try_recv`
/// and never blocks, `block` awaits `recv` on `rt`.
fn iox_wait(
    sub: &mut skymesh_runtime::Subscriber<VehicleState>,
    rt: &tokio::runtime::Runtime,
    mode: Pong,
) -> anyhow::Result<Option<VehicleState>> {
    if mode == Pong::Busy {
        let start = Instant::now();
        while start.elapsed() < IDLE_END {
            if let Some(s) = sub.try_recv()? {
                return Ok(Some(s));
            }
            std::hint::spin_loop();
        }
        return Ok(None);
    }
    Ok(rt.block_on(sub.recv_timeout(IDLE_END))?)
}

/// A tokio current-thread runtime for the receives of `block`.
fn pong_runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?)
}

/// Round trips, one-way ns (round trip / 2); CPU per round trip of ping and pong.
fn ping_pong(domain: &Domain, mode: Pong, n: usize) -> anyhow::Result<(Vec<u64>, f64, f64)> {
    let total = n + WARMUP;
    let mut lat = Vec::with_capacity(n);
    let (child, mut out, cpu) = if mode == Pong::Udp {
        let (child, mut out) = spawn_child(&[
            "--pong".into(),
            mode.arg().into(),
            "-".into(),
            total.to_string(),
        ])?;
        let ready = read_line(&mut out)?;
        let port: u16 = match ready.strip_prefix("ready ") {
            Some(p) => p.parse()?,
            None => anyhow::bail!("pong said `{ready}`"),
        };
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        sock.connect(("127.0.0.1", port))?;
        sock.set_read_timeout(Some(IDLE_END))?;
        let mut buf = [0u8; LEN];
        let mut back = [0u8; LEN + 1];
        let mut cpu0 = 0;
        for k in 0..total {
            if k == WARMUP {
                cpu0 = process_cpu_ns();
            }
            stamp_datagram(&mut buf, VEHICLE, k);
            sock.send(&buf)?;
            let len = retry_interrupted(|| sock.recv(&mut back))?;
            let t1 = monotonic_ns();
            let (seq, t0) = datagram_fields(&back, len, VEHICLE)?;
            anyhow::ensure!(seq == k as u64 + 1, "pong {seq} for ping {}", k + 1);
            if k >= WARMUP {
                lat.push(t1.saturating_sub(t0) / 2);
            }
        }
        (child, out, process_cpu_ns().saturating_sub(cpu0))
    } else {
        let bus = Bus::open(domain, "bench-ping", ServiceId::Tool, 0, Stats::new())?;
        let mut ping = bus.publisher::<VehicleState>(&bench_topic("ping", total))?;
        let mut pong = bus.subscriber::<VehicleState>(&bench_topic("pong", total))?;
        let rt = pong_runtime()?;
        let (child, mut out) = spawn_child(&[
            "--pong".into(),
            mode.arg().into(),
            domain.name.clone(),
            total.to_string(),
        ])?;
        let ready = read_line(&mut out)?;
        anyhow::ensure!(ready == "ready", "pong said `{ready}`");
        std::thread::sleep(Duration::from_millis(200));
        let mut state = bench_state(VEHICLE);
        let mut cpu0 = 0;
        for k in 0..total {
            if k == WARMUP {
                cpu0 = process_cpu_ns();
            }
            state.time_boot_ms = k as u32;
            let t0 = monotonic_ns();
            ping.publish(state)?;
            let Some(s) = iox_wait(&mut pong, &rt, mode)? else {
                anyhow::bail!("no pong for ping {k}");
            };
            let t1 = monotonic_ns();
            anyhow::ensure!(
                s.time_boot_ms == k as u32,
                "pong {} for ping {k}",
                s.time_boot_ms
            );
            if k >= WARMUP {
                lat.push(t1.saturating_sub(t0) / 2);
            }
        }
        (child, out, process_cpu_ns().saturating_sub(cpu0))
    };
    let report = read_line(&mut out)?;
    let pong_cpu: u64 = match report.strip_prefix("cpu ") {
        Some(c) => c.parse()?,
        None => anyhow::bail!("pong said `{report}`"),
    };
    let mut child = child;
    let status = child.wait()?;
    anyhow::ensure!(status.success(), "pong failed: {status}");
    Ok((lat, cpu as f64 / n as f64, pong_cpu as f64 / n as f64))
}

/// The ping-pong partner: returns every ping at once; reports its CPU after warm-up.
fn pong_child(mode: Pong, domain: &str, total: usize) -> anyhow::Result<()> {
    let mut cpu0 = 0;
    if mode == Pong::Udp {
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        sock.set_read_timeout(Some(IDLE_END))?;
        println!("ready {}", sock.local_addr()?.port());
        let mut buf = [0u8; LEN + 1];
        for k in 0..total {
            let (len, from) = retry_interrupted(|| sock.recv_from(&mut buf))?;
            if k == WARMUP {
                cpu0 = process_cpu_ns();
            }
            sock.send_to(&buf[..len], from)?;
        }
    } else {
        let domain = Domain::load(domain, None)?;
        let bus = Bus::open(&domain, "bench-pong", ServiceId::Tool, 0, Stats::new())?;
        let mut ping = bus.subscriber::<VehicleState>(&bench_topic("ping", total))?;
        let mut pong = bus.publisher::<VehicleState>(&bench_topic("pong", total))?;
        let rt = pong_runtime()?;
        println!("ready");
        for k in 0..total {
            let Some(s) = iox_wait(&mut ping, &rt, mode)? else {
                anyhow::bail!("no ping {k}");
            };
            if k == WARMUP {
                cpu0 = process_cpu_ns();
            }
            // Sent back as it came: its header stamp is replaced, the payload is not.
            pong.publish(s)?;
        }
    }
    println!("cpu {}", process_cpu_ns().saturating_sub(cpu0));
    Ok(())
}
