//! Fan-out benchmark (issue 10, item 2): one `VehicleState` from this process to N =
//! 1, 2, 4 and 8 subscriber processes, through the skymesh bus (iceoryx2: one
//! publish, every subscriber woken by the topic's event) vs loopback UDP unicast to
//! each (one `send_to` per subscriber, every child blocked in `recv`), in the same run.
//!
//! ```text
//! cargo run --release -p skymesh-e2e --bin fanout-bench [-- SCALE]
//! ```
//!
//! At 100 Hz (300 messages × SCALE) and 1 kHz (2,000 × SCALE); for each rate and each
//! N, an iceoryx2 phase then a UDP phase, fresh child processes for each phase.
//! Latency = a child's `CLOCK_MONOTONIC` when it holds the message − the send stamp in
//! the message: iceoryx2's `Publisher::publish` stamps `header.stamp_ns` once, then
//! delivers to every subscriber and notifies; the UDP sender stamps once, then does
//! its N `send_to` calls, children in a fixed order (so child i's latency includes the
//! i sends before its own — that is what unicast fan-out costs). Reported per N over
//! all children's messages: p50/p99/p999; "last" = per message, the latency of the
//! slowest child (p50/p99 over messages every child received); sender CPU per message;
//! mean receiver CPU per message (over the children); and UDP ÷ iceoryx2. The first [`WARMUP`] messages of a phase are counted neither in latency
//! nor in CPU.
//!
//! Children wait in the kernel, no spin:
//! - `iox`: `Subscriber::recv` awaited in a tokio current-thread runtime, as the
//!   services receive (woken through the topic's event: the publisher's notify is
//!   one datagram per child);
//! - `udp`: a blocking `std::net::UdpSocket::recv`.

use std::collections::HashMap;
use std::net::UdpSocket;
use std::time::Duration;

use anyhow::{bail, ensure, Result};
use skymesh_e2e::transport_bench::{
    bench_state, datagram_fields, die_with_parent, expect_line, finish_child, percentiles,
    read_line, recv_until_idle, send_loop, spawn_child, stamp_datagram, DomainGuard, Rate,
    RxReport, Tally, DATAGRAM_LEN,
};
use skymesh_ipc_types::{ServiceId, Topic, TopicQos, VehicleState};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, Domain, Stats};

/// Messages at the start of each phase not counted (first wake-ups, page faults).
const WARMUP: usize = 50;
/// Vehicle id written into the bench's samples.
const VEHICLE: u8 = 202;
/// A receiver stops when nothing arrived for this long (the last message was lost).
const IDLE_END: Duration = Duration::from_secs(2);
/// Bytes per UDP datagram: exactly a `VehicleState`.
const LEN: usize = DATAGRAM_LEN;
/// Subscriber counts.
const FANOUT: [usize; 4] = [1, 2, 4, 8];

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("--iox-sub") => {
            die_with_parent()?;
            iox_receiver(&args[2], args[3].parse()?)
        }
        Some("--udp-sub") => {
            die_with_parent()?;
            udp_receiver(args[2].parse()?)
        }
        other => {
            let scale: usize = other.map(str::parse).transpose()?.unwrap_or(1);
            ensure!(scale >= 1, "SCALE must be at least 1");
            driver(scale)
        }
    }
}

/// The bench topic: up to 8 subscribers, a buffer holding 0.5 s at 1 kHz, no history
/// (a phase's subscribers see only its own messages).
fn bench_topic() -> Topic {
    Topic {
        name: format!("skymesh/bench/{VEHICLE}/fanout"),
        qos: TopicQos {
            max_publishers: 1,
            max_subscribers: 8,
            max_nodes: 10,
            history: 0,
            buffer: 512,
        },
    }
}

/// What one phase measured.
struct Phase {
    children: Vec<RxReport>,
    sent: usize,
    tx_cpu: f64,
}

/// Numbers of a phase, as printed.
struct Summary {
    all: [f64; 3],
    last: [f64; 3],
    got: usize,
    expected: usize,
    rx_cpu: f64,
    tx_cpu: f64,
}

impl Phase {
    fn summary(&self) -> Summary {
        let mut all = Vec::new();
        let mut worst: HashMap<usize, (usize, u64)> = HashMap::new();
        for c in &self.children {
            all.extend(c.latencies());
            for &(k, l) in &c.lat {
                let e = worst.entry(k).or_insert((0, 0));
                e.0 += 1;
                e.1 = e.1.max(l);
            }
        }
        let n = self.children.len();
        // Only messages every child counted: a lost one has no "last" receipt.
        let last: Vec<u64> = worst
            .values()
            .filter(|(seen, _)| *seen == n)
            .map(|&(_, l)| l)
            .collect();
        Summary {
            all: percentiles(&all),
            last: percentiles(&last),
            got: self.children.iter().map(|c| c.got).sum(),
            expected: self.sent * n,
            rx_cpu: self.children.iter().map(RxReport::cpu_per_msg).sum::<f64>() / n.max(1) as f64,
            tx_cpu: self.tx_cpu,
        }
    }
}

fn driver(scale: usize) -> Result<()> {
    let name = format!("fo{}", std::process::id());
    let domain = DomainGuard(Domain::load(&name, None)?);
    let plan = [
        (Rate::Hz(100.0), 300 * scale),
        (Rate::Hz(1000.0), 2000 * scale),
    ];
    println!(
        "fanout-bench: VehicleState ({LEN} bytes) from this process to N child processes; \
         iceoryx2 (one publish; async receive in a tokio current-thread runtime) vs loopback UDP (one send_to per child, blocking recv); domain \
         {name}; first {WARMUP} of each phase not counted; latency µs, CPU µs per message \
         (rx = mean over children)"
    );
    println!(
        "{:>6} {:>2} {:>5} | {:>4} {:>11} {:>8} {:>8} {:>8} | {:>8} {:>8} | {:>7} {:>7}",
        "rate",
        "N",
        "sent",
        "via",
        "got",
        "p50",
        "p99",
        "p999",
        "last p50",
        "last p99",
        "tx cpu",
        "rx cpu"
    );
    for (rate, n) in plan {
        for subs in FANOUT {
            let iox = iox_run(&domain.0, rate, n, subs)?.summary();
            let udp = udp_run(rate, n, subs)?.summary();
            for (via, s) in [("iox", &iox), ("udp", &udp)] {
                println!(
                    "{:>6} {:>2} {:>5} | {:>4} {:>11} {:>8.1} {:>8.1} {:>8.1} | {:>8.1} {:>8.1} | {:>7.2} {:>7.2}",
                    rate.label(),
                    subs,
                    n,
                    via,
                    format!("{}/{}", s.got, s.expected),
                    s.all[0] / 1e3,
                    s.all[1] / 1e3,
                    s.all[2] / 1e3,
                    s.last[0] / 1e3,
                    s.last[1] / 1e3,
                    s.tx_cpu / 1e3,
                    s.rx_cpu / 1e3,
                );
            }
            println!(
                "{:>6} {:>2} {:>5} | {:>4} {:>11} {:>8.2} {:>8.2} {:>8.2} | {:>8.2} {:>8.2} | {:>7.2} {:>7.2}",
                rate.label(),
                subs,
                n,
                "u÷i",
                "",
                udp.all[0] / iox.all[0],
                udp.all[1] / iox.all[1],
                udp.all[2] / iox.all[2],
                udp.last[0] / iox.last[0],
                udp.last[1] / iox.last[1],
                udp.tx_cpu / iox.tx_cpu,
                udp.rx_cpu / iox.rx_cpu,
            );
        }
    }
    let left = domain.0.leftover_files();
    drop(domain);
    println!("removed {} leftover shared-memory files", left.len());
    Ok(())
}

fn iox_run(domain: &Domain, rate: Rate, n: usize, subs: usize) -> Result<Phase> {
    // A fresh bus and publisher per phase, so nothing of a previous phase lingers.
    let bus = Bus::open(domain, "bench-fanout-pub", ServiceId::Tool, 0, Stats::new())?;
    let mut publ = bus.publisher::<VehicleState>(&bench_topic())?;
    let mut children = Vec::with_capacity(subs);
    for _ in 0..subs {
        let (child, mut out) =
            spawn_child(&["--iox-sub".into(), domain.name.clone(), n.to_string()])?;
        expect_line(&mut out, "ready")?;
        children.push((child, out));
    }
    std::thread::sleep(Duration::from_millis(100));
    let mut state = bench_state(VEHICLE);
    let tx_cpu = send_loop(rate, n, WARMUP, |k| {
        state.time_boot_ms = k as u32;
        // The bus stamps `header.seq` (k + 1) and `header.stamp_ns` as it sends.
        publ.publish(state)?;
        Ok(())
    })?;
    let reports = children
        .into_iter()
        .map(|(child, out)| finish_child(child, out))
        .collect::<Result<Vec<_>>>()?;
    drop(publ);
    drop(bus);
    Ok(Phase {
        children: reports,
        sent: n,
        tx_cpu,
    })
}

fn iox_receiver(domain: &str, n: usize) -> Result<()> {
    let domain = Domain::load(domain, None)?;
    let bus = Bus::open(
        &domain,
        "bench-fanout-sub",
        ServiceId::Tool,
        0,
        Stats::new(),
    )?;
    let mut tally = Tally::new(n, WARMUP);
    // Waits in the kernel (no spin), as the UDP child blocks in `recv`.
    let mut take = |s: VehicleState| -> Result<bool> {
        let t1 = monotonic_ns();
        ensure!(
            s.vehicle_id == VEHICLE,
            "sample of vehicle {}",
            s.vehicle_id
        );
        let k = s.header.seq.saturating_sub(1) as usize;
        tally.add(k, s.header.stamp_ns, t1);
        Ok(k + 1 >= n)
    };
    let mut sub = bus.subscriber::<VehicleState>(&bench_topic())?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    println!("ready");
    rt.block_on(async {
        while let Some(s) = sub.recv_timeout(IDLE_END).await? {
            if take(s)? {
                break;
            }
        }
        anyhow::Ok(())
    })?;
    tally.report()
}

fn udp_run(rate: Rate, n: usize, subs: usize) -> Result<Phase> {
    let mut children = Vec::with_capacity(subs);
    let mut ports = Vec::with_capacity(subs);
    for _ in 0..subs {
        let (child, mut out) = spawn_child(&["--udp-sub".into(), n.to_string()])?;
        let ready = read_line(&mut out)?;
        let Some(port) = ready.strip_prefix("ready ") else {
            bail!("receiver said `{ready}`");
        };
        ports.push(std::net::SocketAddr::from((
            [127, 0, 0, 1],
            port.parse::<u16>()?,
        )));
        children.push((child, out));
    }
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    std::thread::sleep(Duration::from_millis(100));
    // The same bytes a VehicleState has; sequence and send time where its header keeps them.
    let mut buf = [0u8; LEN];
    let tx_cpu = send_loop(rate, n, WARMUP, |k| {
        stamp_datagram(&mut buf, VEHICLE, k);
        for to in &ports {
            let sent = sock.send_to(&buf, to)?;
            ensure!(sent == LEN, "sent {sent} of {LEN} bytes");
        }
        Ok(())
    })?;
    let reports = children
        .into_iter()
        .map(|(child, out)| finish_child(child, out))
        .collect::<Result<Vec<_>>>()?;
    Ok(Phase {
        children: reports,
        sent: n,
        tx_cpu,
    })
}

fn udp_receiver(n: usize) -> Result<()> {
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_read_timeout(Some(IDLE_END))?;
    let mut tally = Tally::new(n, WARMUP);
    println!("ready {}", sock.local_addr()?.port());
    let mut buf = [0u8; LEN + 1];
    while let Some(len) = recv_until_idle(&sock, &mut buf)? {
        let t1 = monotonic_ns();
        let (seq, t0) = datagram_fields(&buf, len, VEHICLE)?;
        let k = seq.saturating_sub(1) as usize;
        tally.add(k, t0, t1);
        if k + 1 >= n {
            break;
        }
    }
    tally.report()
}
