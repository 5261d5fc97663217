//! What the process-to-process transport benchmarks (`fanout-bench`, `frames-bench`,
//! `samples-bench`) share: percentiles over nanoseconds, process CPU time, pacing,
//! child processes (the benchmark binary re-executed with a hidden first argument,
//! talking back over its stdout) and the receiver's tally and report.
//!
//! Report protocol, child → parent, on the child's stdout: first a line the parent
//! waits for (`ready`, or `ready <port>`), then, at the end,
//! `got <received> <cpu_ns> <counted>` followed by one `<k> <latency_ns>` line per
//! counted message (`k` = the message's index in the phase, from 0).

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, ensure, Result};
use skymesh_ipc_types::VehicleState;

/// p50, p99 and p999 (nearest rank) of `v` in ns; NaN when `v` is empty.
pub fn percentiles(v: &[u64]) -> [f64; 3] {
    if v.is_empty() {
        return [f64::NAN; 3];
    }
    let mut v = v.to_vec();
    v.sort_unstable();
    let at = |q: f64| v[((v.len() as f64 * q) as usize).min(v.len() - 1)] as f64;
    [at(0.50), at(0.99), at(0.999)]
}

/// CPU time of this process (all threads, user + system, `CLOCK_PROCESS_CPUTIME_ID`), ns.
pub fn process_cpu_ns() -> u64 {
    clock_ns(nix::time::ClockId::CLOCK_PROCESS_CPUTIME_ID)
}

fn clock_ns(clock: nix::time::ClockId) -> u64 {
    match nix::time::clock_gettime(clock) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000) + ts.tv_nsec() as u64,
        Err(_) => 0,
    }
}

/// CPU time of the calling thread (user + system, `CLOCK_THREAD_CPUTIME_ID`), ns. A
/// system call (the vDSO does not serve CPU-time clocks): read it outside what it
/// measures, as [`SendSlot`] does.
pub fn thread_cpu_ns() -> u64 {
    clock_ns(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID)
}

/// The sender's CPU for one send, told apart from the sends to other receivers of
/// an interleaved phase and from the pacing sleep between them: three reads of the
/// thread's CPU clock, `c0 c1 send c2`; `(c2 − c1) − (c1 − c0)` is the send, the
/// clock's own cost (a system call between two samples) taken out by the empty
/// interval before it.
#[derive(Debug, Default, Clone, Copy)]
pub struct SendSlot {
    /// Summed CPU of the counted sends, ns (signed: one send's estimate can be
    /// below zero when the empty interval was the slower one).
    pub sum_ns: i64,
    pub counted: usize,
}

impl SendSlot {
    /// Runs `send`, adding its CPU when `counted`.
    pub fn time<R>(&mut self, counted: bool, send: impl FnOnce() -> R) -> R {
        let c0 = thread_cpu_ns();
        let c1 = thread_cpu_ns();
        let r = send();
        let c2 = thread_cpu_ns();
        if counted {
            self.sum_ns += (c2 as i64 - c1 as i64) - (c1 as i64 - c0 as i64);
            self.counted += 1;
        }
        r
    }

    /// CPU per counted send, ns (NaN before any).
    pub fn per_msg(&self) -> f64 {
        if self.counted == 0 {
            return f64::NAN;
        }
        self.sum_ns as f64 / self.counted as f64
    }
}

/// How fast a sender goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    Hz(f64),
    BackToBack,
}

impl Rate {
    /// `100 Hz`, `1 kHz`, `b2b`.
    pub fn label(self) -> String {
        match self {
            Rate::Hz(hz) if hz >= 1000.0 => format!("{} kHz", hz / 1000.0),
            Rate::Hz(hz) => format!("{hz} Hz"),
            Rate::BackToBack => "b2b".to_string(),
        }
    }
}

/// Paces a send loop on absolute deadlines (a late message does not shift the rest).
#[derive(Debug)]
pub struct Pacer {
    start: Instant,
    period: Option<Duration>,
    n: u32,
}

impl Pacer {
    pub fn new(rate: Rate) -> Pacer {
        Pacer {
            start: Instant::now(),
            period: match rate {
                Rate::Hz(hz) => Some(Duration::from_secs_f64(1.0 / hz)),
                Rate::BackToBack => None,
            },
            n: 0,
        }
    }

    /// Sleeps until the next message is due (at once back to back).
    pub fn wait(&mut self) {
        let Some(period) = self.period else { return };
        let due = self.start + period * self.n;
        self.n += 1;
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
}

/// Starts this executable again with `args`, its stdout piped back.
pub fn spawn_child(args: &[String]) -> Result<(Child, BufReader<ChildStdout>)> {
    let mut child = Command::new(std::env::current_exe()?)
        .args(args)
        .stdout(Stdio::piped())
        .spawn()?;
    let Some(out) = child.stdout.take() else {
        bail!("child has no stdout");
    };
    Ok((child, BufReader::new(out)))
}

/// For a bench's receiving child, first thing: the kernel kills it when the bench
/// that spawned it exits, however that happens (a phase that fails, a panic, ^C), so
/// no receiver is left blocked in a wait without a timeout (`samples-bench`'s
/// `iox-raw` and `iox-word` have none, on purpose). Spawn children from the main
/// thread: the signal follows the spawning thread.
pub fn die_with_parent() -> Result<()> {
    nix::sys::prctl::set_pdeathsig(Some(nix::sys::signal::Signal::SIGKILL))?;
    // The parent may have gone before the call: then this process was re-parented.
    ensure!(
        nix::unistd::getppid() != nix::unistd::Pid::from_raw(1),
        "the bench that started this receiver has exited"
    );
    Ok(())
}

/// One line of a child's stdout, trimmed.
pub fn read_line(out: &mut BufReader<ChildStdout>) -> Result<String> {
    let mut line = String::new();
    out.read_line(&mut line)?;
    Ok(line.trim().to_string())
}

/// Reads one line and fails unless it is `want`.
pub fn expect_line(out: &mut BufReader<ChildStdout>, want: &str) -> Result<()> {
    let line = read_line(out)?;
    ensure!(line == want, "child said `{line}` instead of `{want}`");
    Ok(())
}

/// What one receiving child measured.
#[derive(Debug, Clone, Default)]
pub struct RxReport {
    /// Messages received (warm-up included).
    pub got: usize,
    /// Receiver CPU over the counted part, ns.
    pub cpu_ns: u64,
    /// `(k, latency ns)` of every counted message.
    pub lat: Vec<(usize, u64)>,
}

impl RxReport {
    /// Receiver CPU per counted message, ns.
    pub fn cpu_per_msg(&self) -> f64 {
        self.cpu_ns as f64 / self.lat.len().max(1) as f64
    }

    /// The latencies alone.
    pub fn latencies(&self) -> Vec<u64> {
        self.lat.iter().map(|&(_, l)| l).collect()
    }
}

/// Reads a child's report (see the module doc) and waits for it to exit successfully.
pub fn finish_child(mut child: Child, mut out: BufReader<ChildStdout>) -> Result<RxReport> {
    let head = read_line(&mut out)?;
    let f: Vec<&str> = head.split_whitespace().collect();
    ensure!(
        f.len() == 4 && f[0] == "got",
        "receiver said `{head}` instead of its report"
    );
    let (got, cpu_ns, counted): (usize, u64, usize) = (f[1].parse()?, f[2].parse()?, f[3].parse()?);
    let mut lat = Vec::with_capacity(counted);
    for line in out.lines() {
        let line = line?;
        let Some((k, l)) = line.trim().split_once(' ') else {
            bail!("receiver said `{line}` instead of `<k> <latency>`");
        };
        lat.push((k.parse()?, l.parse()?));
    }
    let status = child.wait()?;
    ensure!(status.success(), "receiver failed: {status}");
    ensure!(
        lat.len() == counted,
        "receiver announced {counted} latencies, sent {}",
        lat.len()
    );
    Ok(RxReport { got, cpu_ns, lat })
}

/// What a receiving child accumulates, whatever the transport.
#[derive(Debug)]
pub struct Tally {
    n: usize,
    warmup: usize,
    got: usize,
    lat: Vec<(usize, u64)>,
    cpu0: Option<u64>,
    /// Read once, after the last message (or, if it was lost, at [`Tally::report`]):
    /// reading the process CPU clock is a system call, which per message would add
    /// to what is measured.
    cpu1: Option<u64>,
}

impl Tally {
    /// A tally for up to `n` messages whose first `warmup` are not counted.
    pub fn new(n: usize, warmup: usize) -> Tally {
        Tally {
            n,
            warmup,
            got: 0,
            lat: Vec::with_capacity(n),
            cpu0: None,
            cpu1: None,
        }
    }

    /// Records message `k` sent at `t0`, received at `t1` (both `CLOCK_MONOTONIC` ns),
    /// after the receiver has handled it. CPU is counted from the end of the handling
    /// of the last warm-up message to the end of the last message's (`k` = `n` - 1;
    /// if that one is lost, to the report).
    pub fn add(&mut self, k: usize, t0: u64, t1: u64) {
        self.got += 1;
        if k >= self.warmup && self.cpu0.is_some() {
            self.lat.push((k, t1.saturating_sub(t0)));
        }
        if k + 1 >= self.warmup && self.cpu0.is_none() {
            self.cpu0 = Some(process_cpu_ns());
        }
        if k + 1 >= self.n && self.cpu1.is_none() {
            self.cpu1 = Some(process_cpu_ns());
        }
    }

    /// Writes the report to stdout (see the module doc).
    pub fn report(self) -> Result<()> {
        let cpu1 = self.cpu1.unwrap_or_else(process_cpu_ns);
        let cpu = cpu1.saturating_sub(self.cpu0.unwrap_or(cpu1));
        let mut out = std::io::stdout().lock();
        writeln!(out, "got {} {} {}", self.got, cpu, self.lat.len())?;
        for (k, l) in self.lat {
            writeln!(out, "{k} {l}")?;
        }
        out.flush()?;
        Ok(())
    }
}

/// Sender CPU over the counted part of a send loop: call [`SendCpu::at`] before
/// sending each message `k`, then [`SendCpu::per_msg`].
#[derive(Debug)]
pub struct SendCpu {
    warmup: usize,
    cpu0: u64,
    counted: usize,
}

impl SendCpu {
    pub fn new(warmup: usize) -> SendCpu {
        SendCpu {
            warmup,
            cpu0: process_cpu_ns(),
            counted: 0,
        }
    }

    /// Before message `k` is sent.
    pub fn at(&mut self, k: usize) {
        if k == self.warmup {
            self.cpu0 = process_cpu_ns();
        }
        if k >= self.warmup {
            self.counted += 1;
        }
    }

    /// CPU per counted message so far, ns.
    pub fn per_msg(&self) -> f64 {
        process_cpu_ns().saturating_sub(self.cpu0) as f64 / self.counted.max(1) as f64
    }
}

/// Sends `n` messages at `rate` through `send(k)`; returns the sender's CPU per
/// message after the first `warmup`, ns.
pub fn send_loop(
    rate: Rate,
    n: usize,
    warmup: usize,
    mut send: impl FnMut(usize) -> Result<()>,
) -> Result<f64> {
    let mut pace = Pacer::new(rate);
    let mut cpu = SendCpu::new(warmup);
    for k in 0..n {
        pace.wait();
        cpu.at(k);
        send(k)?;
    }
    Ok(cpu.per_msg())
}

/// The `VehicleState` the small-sample benches send: a hovering vehicle with valid
/// position and attitude (contents do not matter to the transport; its size does).
pub fn bench_state(vehicle_id: u8) -> VehicleState {
    VehicleState {
        vehicle_id,
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

/// Bytes of the UDP baseline's datagram: exactly a `VehicleState`, so both
/// transports carry the same payload.
pub const DATAGRAM_LEN: usize = std::mem::size_of::<VehicleState>();

/// Writes the UDP baseline's datagram for message `k` of `vehicle_id`: the sequence
/// (k + 1) and the send time (`CLOCK_MONOTONIC` ns, taken now) where a
/// `VehicleState`'s header keeps them, and the vehicle id where it keeps it.
pub fn stamp_datagram(buf: &mut [u8; DATAGRAM_LEN], vehicle_id: u8, k: usize) {
    buf[24] = vehicle_id;
    buf[..8].copy_from_slice(&(k as u64 + 1).to_le_bytes());
    buf[8..16].copy_from_slice(&skymesh_runtime::clock::monotonic_ns().to_le_bytes());
}

/// (sequence, send stamp) of a received baseline datagram of `len` bytes, checked
/// for its size and vehicle id.
pub fn datagram_fields(buf: &[u8], len: usize, vehicle_id: u8) -> Result<(u64, u64)> {
    ensure!(
        len == DATAGRAM_LEN,
        "datagram of {len} bytes, expected {DATAGRAM_LEN}"
    );
    ensure!(buf[24] == vehicle_id, "sample of vehicle {}", buf[24]);
    let field = |i: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&buf[i..i + 8]);
        u64::from_le_bytes(b)
    };
    Ok((field(0), field(8)))
}

/// A blocking receive on a socket with a read timeout: `None` once nothing came for
/// that long (the phase is over, or its last message was lost).
pub fn recv_until_idle(sock: &std::net::UdpSocket, buf: &mut [u8]) -> Result<Option<usize>> {
    match retry_interrupted(|| sock.recv(buf)) {
        Ok(len) => Ok(Some(len)),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}

/// `io` again while it is interrupted by a signal. A tracer attaching (`strace -p`)
/// interrupts a receive on a socket with a read timeout, which the kernel does not
/// restart (`EINTR`): every timed receive of the benches goes through this.
pub fn retry_interrupted<T>(mut io: impl FnMut() -> std::io::Result<T>) -> std::io::Result<T> {
    loop {
        match io() {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            r => return r,
        }
    }
}

/// An iceoryx2 domain whose shared-memory files are removed however the run ends.
pub use skymesh_runtime::ipc::DomainGuard;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interrupted_receive_is_tried_again() {
        use std::io::{Error, ErrorKind};
        let mut results = vec![
            Ok(7),
            Err(Error::from(ErrorKind::Interrupted)),
            Err(Error::from(ErrorKind::Interrupted)),
        ];
        assert_eq!(retry_interrupted(|| results.pop().unwrap()).unwrap(), 7);
        assert!(results.is_empty());
        // Nothing comes: the phase is over, not an error.
        let idle = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        idle.set_read_timeout(Some(std::time::Duration::from_millis(10)))
            .unwrap();
        assert_eq!(recv_until_idle(&idle, &mut [0u8; 8]).unwrap(), None);
        let mut refused = vec![Err::<usize, _>(Error::from(ErrorKind::ConnectionRefused))];
        assert_eq!(
            retry_interrupted(|| refused.pop().unwrap())
                .unwrap_err()
                .kind(),
            ErrorKind::ConnectionRefused
        );
    }

    #[test]
    fn percentiles_nearest_rank() {
        let v: Vec<u64> = (1..=1000).collect();
        assert_eq!(percentiles(&v), [501.0, 991.0, 1000.0]);
        assert!(percentiles(&[]).iter().all(|p| p.is_nan()));
    }

    #[test]
    fn tally_skips_warmup() {
        let mut t = Tally::new(10, 2);
        for k in 0..5 {
            t.add(k, 100, 150 + k as u64);
        }
        assert_eq!(t.got, 5);
        assert_eq!(t.lat, vec![(2, 52), (3, 53), (4, 54)]);
    }

    #[test]
    fn tally_reads_the_cpu_clock_at_the_warmup_end_and_the_last_message_only() {
        let mut t = Tally::new(4, 2);
        t.add(0, 100, 150);
        assert!(t.cpu0.is_none() && t.cpu1.is_none());
        t.add(1, 100, 150);
        assert!(t.cpu0.is_some(), "the counted CPU starts after the warm-up");
        t.add(2, 100, 150);
        assert!(
            t.cpu1.is_none(),
            "a system call per message would be measured"
        );
        t.add(3, 100, 150);
        assert!(t.cpu1.is_some(), "the last message ends the counted CPU");
    }

    /// A send's CPU is what it burns on the thread: a send that works until the
    /// thread's CPU clock has advanced 5 ms is measured at about that, the clock's own
    /// cost taken out; uncounted sends add nothing. (CPU time of the thread itself,
    /// not wall time: load on the machine does not change it.)
    #[test]
    fn send_slot_measures_the_send_and_counts_only_counted_sends() {
        let burn = |ms: u64| {
            let t0 = thread_cpu_ns();
            while thread_cpu_ns() - t0 < ms * 1_000_000 {
                std::hint::spin_loop();
            }
        };
        let mut slot = SendSlot::default();
        assert!(slot.per_msg().is_nan(), "nothing counted yet");
        slot.time(false, || burn(20));
        assert_eq!(slot.counted, 0);
        assert_eq!(slot.sum_ns, 0);
        let r = slot.time(true, || {
            burn(5);
            7
        });
        assert_eq!(r, 7, "the send's result is handed back");
        assert_eq!(slot.counted, 1);
        let ms = slot.per_msg() / 1e6;
        assert!((5.0..6.0).contains(&ms), "measured {ms} ms for a 5 ms send");
    }
}
