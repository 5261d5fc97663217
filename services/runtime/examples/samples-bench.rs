//! Small-sample transport benchmark (issue 10, item 1): a `VehicleState` sent one way
//! from this process to a child process, through the skymesh bus (iceoryx2, the
//! child awaiting `Subscriber::recv` in a tokio current-thread runtime: event
//! wake-up, the way every service receives) vs loopback UDP with a blocking `recv`
//! (`std::net::UdpSocket`) carrying the same number of bytes, in the same run.
//!
//! ```text
//! cargo run --release -p skymesh-runtime --example samples-bench [-- SCALE]
//! ```
//!
//! At 100 Hz (500 messages), 1 kHz (2,000) and back to back (2,000, as fast as the
//! sender can go), iceoryx2 then UDP for each rate; `SCALE` multiplies the counts.
//! Latency = the receiver's `CLOCK_MONOTONIC` when it has the sample − the send
//! timestamp carried in the sample (the bus stamps `header.stamp_ns` just before
//! sending; the UDP sender writes the same clock just before `send`). The first
//! [`WARMUP`] messages of each phase are not counted, neither in latency nor in CPU.
//! CPU per message is `CLOCK_PROCESS_CPUTIME_ID` (user + system, what `getrusage`
//! sums) before/after the counted part of each phase, on each side.
//!
//! The bus topic is the real `skymesh/vehicle/{id}/state` with its `STATE` QoS: a
//! buffer of 8 where the newest sample wins, so back to back the subscriber loses
//! most samples (counted in `got`), while UDP queues in the socket buffer (and drops
//! when that is full). Lost samples are not in the percentiles. So the back-to-back
//! phase runs twice for iceoryx2: on the state topic (`iox`), and on a bench topic
//! whose subscriber buffer holds the whole phase (`iox*`, nothing overwritten, the
//! queueing comparable with UDP's).

use std::io::{BufRead, BufReader, Write};
use std::net::UdpSocket;
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use skymesh_ipc_types::{topics, ServiceId, Topic, TopicQos, VehicleState};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, Domain, Stats};

/// Messages at the start of each phase not counted (first wake-ups, page faults).
const WARMUP: usize = 50;
/// Vehicle id of the benchmark's state topic.
const VEHICLE: u8 = 201;
/// The receiver stops when nothing arrived for this long (the last message was lost).
const IDLE_END: Duration = Duration::from_secs(2);
/// Bytes per UDP datagram: exactly a `VehicleState`.
const LEN: usize = std::mem::size_of::<VehicleState>();

/// How fast the sender goes.
#[derive(Debug, Clone, Copy)]
enum Rate {
    Hz(f64),
    BackToBack,
}

impl Rate {
    fn label(self) -> String {
        match self {
            Rate::Hz(hz) if hz >= 1000.0 => format!("{} kHz", hz / 1000.0),
            Rate::Hz(hz) => format!("{hz} Hz"),
            Rate::BackToBack => "b2b".to_string(),
        }
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("--iox-sub") => iox_receiver(&args[2], args[3].parse()?, args[4] == "burst"),
        Some("--udp-sub") => udp_receiver(args[2].parse()?),
        other => {
            let scale: usize = other.map(str::parse).transpose()?.unwrap_or(1);
            anyhow::ensure!(scale >= 1, "SCALE must be at least 1");
            driver(scale)
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

/// Which bus topic a phase uses.
fn bench_topic(n: usize, burst: bool) -> Topic {
    if burst {
        Topic {
            name: format!("skymesh/bench/{VEHICLE}/state_burst"),
            qos: TopicQos {
                max_publishers: 1,
                max_subscribers: 1,
                max_nodes: 4,
                history: 0,
                buffer: n,
            },
        }
    } else {
        topics::vehicle_state(VEHICLE)
    }
}

/// Removes the domain's shared-memory files however the run ends.
struct DomainGuard(Domain);

impl Drop for DomainGuard {
    fn drop(&mut self) {
        self.0.remove_leftover_files();
    }
}

fn driver(scale: usize) -> anyhow::Result<()> {
    let name = format!("sb{}", std::process::id());
    let domain = DomainGuard(Domain::load(&name, None)?);
    let plan = [
        (Rate::Hz(100.0), 500 * scale),
        (Rate::Hz(1000.0), 2000 * scale),
        (Rate::BackToBack, 2000 * scale),
    ];
    println!(
        "samples-bench: VehicleState ({LEN} bytes) one way parent → child process; \
         iceoryx2 (tokio, event wake-up) vs loopback UDP (blocking recv); domain {name}; \
         first {WARMUP} of each phase not counted; latency µs, CPU µs per message"
    );
    println!(
        "{:>7} {:>5} | {:>4} {:>10} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "rate", "sent", "via", "got", "p50", "p99", "p999", "rx cpu", "tx cpu"
    );
    for (rate, n) in plan {
        let iox = iox_run(&domain.0, rate, n, false)?;
        let udp = udp_run(rate, n)?;
        let burst = match rate {
            Rate::BackToBack => Some(iox_run(&domain.0, rate, n, true)?),
            Rate::Hz(_) => None,
        };
        let pi = percentiles(&iox.lat);
        let pu = percentiles(&udp.lat);
        let mut rows = vec![("iox", &iox, pi), ("udp", &udp, pu)];
        if let Some(b) = &burst {
            rows.push(("iox*", b, percentiles(&b.lat)));
        }
        for (via, ph, p) in rows {
            println!(
                "{:>7} {:>5} | {:>4} {:>10} {:>8.1} {:>8.1} {:>8.1} {:>8.2} {:>8.2}",
                rate.label(),
                ph.sent,
                via,
                format!("{}/{}", ph.got, ph.sent),
                p[0] / 1e3,
                p[1] / 1e3,
                p[2] / 1e3,
                ph.rx_cpu / 1e3,
                ph.tx_cpu / 1e3,
            );
        }
        println!(
            "{:>7} {:>5} | {:>4} {:>10} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
            rate.label(),
            n,
            "u÷i",
            "",
            pu[0] / pi[0],
            pu[1] / pi[1],
            pu[2] / pi[2],
            udp.rx_cpu / iox.rx_cpu,
            udp.tx_cpu / iox.tx_cpu,
        );
        if let Some(b) = &burst {
            let pb = percentiles(&b.lat);
            println!(
                "{:>7} {:>5} | {:>4} {:>10} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
                rate.label(),
                n,
                "u÷i*",
                "",
                pu[0] / pb[0],
                pu[1] / pb[1],
                pu[2] / pb[2],
                udp.rx_cpu / b.rx_cpu,
                udp.tx_cpu / b.tx_cpu,
            );
        }
    }
    let left = domain.0.leftover_files();
    drop(domain);
    println!("removed {} leftover shared-memory files", left.len());
    Ok(())
}

/// p50, p99, p999 in ns (NaN when nothing was counted).
fn percentiles(v: &[u64]) -> [f64; 3] {
    if v.is_empty() {
        return [f64::NAN; 3];
    }
    let mut v = v.to_vec();
    v.sort_unstable();
    let at = |q: f64| v[((v.len() as f64 * q) as usize).min(v.len() - 1)] as f64;
    [at(0.50), at(0.99), at(0.999)]
}

/// CPU time of this process (all threads, user + system), ns.
fn process_cpu_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_PROCESS_CPUTIME_ID) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000) + ts.tv_nsec() as u64,
        Err(_) => 0,
    }
}

/// Paces a send loop (absolute deadlines, so a late message does not shift the rest).
struct Pacer {
    start: Instant,
    period: Option<Duration>,
    n: u32,
}

impl Pacer {
    fn new(rate: Rate) -> Pacer {
        Pacer {
            start: Instant::now(),
            period: match rate {
                Rate::Hz(hz) => Some(Duration::from_secs_f64(1.0 / hz)),
                Rate::BackToBack => None,
            },
            n: 0,
        }
    }

    fn wait(&mut self) {
        let Some(period) = self.period else { return };
        let due = self.start + period * self.n;
        self.n += 1;
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
}

fn spawn_child(args: &[String]) -> anyhow::Result<(Child, BufReader<ChildStdout>)> {
    let mut child = Command::new(std::env::current_exe()?)
        .args(args)
        .stdout(Stdio::piped())
        .spawn()?;
    let Some(out) = child.stdout.take() else {
        anyhow::bail!("child has no stdout");
    };
    Ok((child, BufReader::new(out)))
}

fn read_line(out: &mut BufReader<ChildStdout>) -> anyhow::Result<String> {
    let mut line = String::new();
    out.read_line(&mut line)?;
    Ok(line.trim().to_string())
}

/// Sends `n` messages at `rate` through `send(k)`; returns sender CPU per counted one.
fn send_loop(
    rate: Rate,
    n: usize,
    mut send: impl FnMut(usize) -> anyhow::Result<()>,
) -> anyhow::Result<f64> {
    let mut pace = Pacer::new(rate);
    let mut cpu0 = process_cpu_ns();
    for k in 0..n {
        pace.wait();
        if k == WARMUP {
            cpu0 = process_cpu_ns();
        }
        send(k)?;
    }
    let cpu = process_cpu_ns().saturating_sub(cpu0);
    Ok(cpu as f64 / (n - WARMUP) as f64)
}

/// Reads the receiver's report: `got <n> <cpu_ns> <counted>`, then one latency per line.
fn finish(
    mut child: Child,
    mut out: BufReader<ChildStdout>,
    sent: usize,
    tx_cpu: f64,
) -> anyhow::Result<Phase> {
    let head = read_line(&mut out)?;
    let f: Vec<&str> = head.split_whitespace().collect();
    anyhow::ensure!(
        f.len() == 4 && f[0] == "got",
        "receiver said `{head}` instead of its report"
    );
    let (got, cpu, counted): (usize, u64, usize) = (f[1].parse()?, f[2].parse()?, f[3].parse()?);
    let mut lat = Vec::with_capacity(counted);
    for line in out.lines() {
        lat.push(line?.trim().parse()?);
    }
    let status = child.wait()?;
    anyhow::ensure!(status.success(), "receiver failed: {status}");
    Ok(Phase {
        lat,
        got,
        sent,
        rx_cpu: cpu as f64 / counted.max(1) as f64,
        tx_cpu,
    })
}

/// What the receiver accumulates, the same for both transports.
struct Tally {
    got: usize,
    lat: Vec<u64>,
    cpu0: Option<u64>,
    cpu1: u64,
}

impl Tally {
    fn new(n: usize) -> Tally {
        Tally {
            got: 0,
            lat: Vec::with_capacity(n),
            cpu0: None,
            cpu1: 0,
        }
    }

    /// Records message `k` sent at `t0`, received at `t1`.
    fn add(&mut self, k: usize, t0: u64, t1: u64) {
        self.got += 1;
        if k >= WARMUP {
            // CPU is counted from the end of the last warm-up message's handling.
            if self.cpu0.is_some() {
                self.lat.push(t1.saturating_sub(t0));
            }
        }
        if k + 1 >= WARMUP && self.cpu0.is_none() {
            self.cpu0 = Some(process_cpu_ns());
        }
        self.cpu1 = process_cpu_ns();
    }

    fn report(self) -> anyhow::Result<()> {
        let cpu = self.cpu1.saturating_sub(self.cpu0.unwrap_or(self.cpu1));
        let mut out = std::io::stdout().lock();
        writeln!(out, "got {} {} {}", self.got, cpu, self.lat.len())?;
        for l in self.lat {
            writeln!(out, "{l}")?;
        }
        Ok(())
    }
}

fn iox_run(domain: &Domain, rate: Rate, n: usize, burst: bool) -> anyhow::Result<Phase> {
    // A fresh bus and publisher per phase: the topic keeps a history of 1, which a
    // reused publisher would hand the next phase's subscriber.
    let bus = Bus::open(domain, "bench-state-pub", ServiceId::Tool, 0, Stats::new())?;
    let mut publ = bus.publisher::<VehicleState>(&bench_topic(n, burst))?;
    let (child, mut out) = spawn_child(&[
        "--iox-sub".into(),
        domain.name.clone(),
        n.to_string(),
        if burst { "burst" } else { "state" }.into(),
    ])?;
    let ready = read_line(&mut out)?;
    anyhow::ensure!(ready == "ready", "receiver said `{ready}`");
    std::thread::sleep(Duration::from_millis(100));
    let mut state = sample_state();
    let tx_cpu = send_loop(rate, n, |k| {
        state.time_boot_ms = k as u32;
        // The bus stamps `header.seq` (k + 1) and `header.stamp_ns` as it sends.
        publ.publish(state)?;
        Ok(())
    })?;
    let phase = finish(child, out, n, tx_cpu)?;
    drop(publ);
    drop(bus);
    Ok(phase)
}

fn iox_receiver(domain: &str, n: usize, burst: bool) -> anyhow::Result<()> {
    let domain = Domain::load(domain, None)?;
    let bus = Bus::open(&domain, "bench-state-sub", ServiceId::Tool, 0, Stats::new())?;
    let mut sub = bus.subscriber::<VehicleState>(&bench_topic(n, burst))?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let mut tally = Tally::new(n);
    println!("ready");
    rt.block_on(async {
        while let Some(s) = sub.recv_timeout(IDLE_END).await? {
            let t1 = monotonic_ns();
            anyhow::ensure!(
                s.vehicle_id == VEHICLE,
                "sample of vehicle {}",
                s.vehicle_id
            );
            let k = s.header.seq.saturating_sub(1) as usize;
            tally.add(k, s.header.stamp_ns, t1);
            if k + 1 >= n {
                break;
            }
        }
        anyhow::Ok(())
    })?;
    tally.report()
}

/// A plausible state (values do not matter to either transport, size does).
fn sample_state() -> VehicleState {
    VehicleState {
        vehicle_id: VEHICLE,
        position_valid: 1,
        attitude_valid: 1,
        lat_deg: 47.397_742,
        lon_deg: 8.545_594,
        alt_msl_m: 488.0,
        alt_rel_m: 20.0,
        attitude_q: [1.0, 0.0, 0.0, 0.0],
        ..VehicleState::default()
    }
}

fn udp_run(rate: Rate, n: usize) -> anyhow::Result<Phase> {
    let (child, mut out) = spawn_child(&["--udp-sub".into(), n.to_string()])?;
    let ready = read_line(&mut out)?;
    let port: u16 = match ready.strip_prefix("ready ") {
        Some(p) => p.parse()?,
        None => anyhow::bail!("receiver said `{ready}`"),
    };
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.connect(("127.0.0.1", port))?;
    std::thread::sleep(Duration::from_millis(100));
    // The same bytes a VehicleState has; sequence and send time where its header keeps them.
    let mut buf = [0u8; LEN];
    buf[24] = VEHICLE;
    let tx_cpu = send_loop(rate, n, |k| {
        buf[..8].copy_from_slice(&(k as u64 + 1).to_le_bytes());
        buf[8..16].copy_from_slice(&monotonic_ns().to_le_bytes());
        let sent = sock.send(&buf)?;
        anyhow::ensure!(sent == LEN, "sent {sent} of {LEN} bytes");
        Ok(())
    })?;
    finish(child, out, n, tx_cpu)
}

fn udp_receiver(n: usize) -> anyhow::Result<()> {
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_read_timeout(Some(IDLE_END))?;
    let mut tally = Tally::new(n);
    println!("ready {}", sock.local_addr()?.port());
    let mut buf = [0u8; LEN + 1];
    loop {
        let len = match sock.recv(&mut buf) {
            Ok(len) => len,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                break
            }
            Err(e) => return Err(e.into()),
        };
        let t1 = monotonic_ns();
        anyhow::ensure!(len == LEN, "datagram of {len} bytes, expected {LEN}");
        anyhow::ensure!(buf[24] == VEHICLE, "sample of vehicle {}", buf[24]);
        let field = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&buf[i..i + 8]);
            u64::from_le_bytes(b)
        };
        let k = field(0).saturating_sub(1) as usize;
        tally.add(k, field(8), t1);
        if k + 1 >= n {
            break;
        }
    }
    tally.report()
}
