//! What skymesh adds to iceoryx2 on a cold cache (issue 10, small samples at 100 Hz):
//! one publish and one receive of a `VehicleState`, each right after the caches and
//! TLBs were flushed by walking a 64 MiB buffer — the state a receiver wakes into
//! after 10 ms asleep while other processes ran — through skymesh's `Publisher` /
//! `Subscriber` and through raw iceoryx2 ports in the same process, interleaved.
//!
//! ```text
//! cargo run --release -p skymesh-e2e --bin cold-bench [-- ROUNDS]
//! ```
//!
//! Raw iceoryx2: `send_copy` + `notify` on the thread-safe service flavour skymesh
//! uses (`ipc_threadsafe`); receive + copy + release. skymesh: `publish` (header
//! stamp, send, notify, counter) and `try_recv` (receive, copy, release, then the
//! subscriber's accounting: received counter, age histogram, gap table).
//! Prints p50 / p99 per operation and the p50 of the per-round difference
//! skymesh − raw, in ns. One thread, no wake-ups:
//! the cost of touching memory, not of the kernel.

use std::hint::black_box;

use anyhow::{anyhow, Result};
use iceoryx2::prelude::*;
use skymesh_e2e::transport_bench::percentiles;
use skymesh_ipc_types::{ServiceId, Topic, TopicQos, VehicleState};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, Domain, Stats};

/// Larger than the last-level cache and the TLB reach of 4 KiB pages.
const FLUSH_BYTES: usize = 64 << 20;

fn flush(buf: &mut [u8], k: usize) {
    for i in (0..buf.len()).step_by(64) {
        buf[i] = buf[i].wrapping_add(k as u8);
    }
    black_box(&buf);
}

/// Times `op` after a flush, in ns.
fn cold<T>(buf: &mut [u8], k: usize, op: impl FnOnce() -> T) -> (u64, T) {
    flush(buf, k);
    let t0 = monotonic_ns();
    let r = op();
    (monotonic_ns() - t0, r)
}

/// A cold raw iceoryx2 receive + copy + release: its time (ns) and the sample's sequence.
fn raw_receive(
    sub: &iceoryx2::port::subscriber::Subscriber<ipc_threadsafe::Service, VehicleState, ()>,
    buf: &mut [u8],
    k: usize,
) -> Result<(u64, u64)> {
    let (ns, v) = cold(buf, k, || {
        sub.receive()
            .map(|o| o.map(|smp| -> VehicleState { *smp.payload() }))
    });
    let v = v
        .map_err(|e| anyhow!("iceoryx2 receive: {e:?}"))?
        .ok_or_else(|| anyhow!("raw: no sample"))?;
    Ok((ns, v.header.seq))
}

fn main() -> Result<()> {
    let mut rounds = 1000usize;
    for a in std::env::args().skip(1) {
        rounds = a
            .parse()
            .map_err(|_| anyhow!("usage: cold-bench [ROUNDS]"))?;
    }
    let name = format!("cb{}", std::process::id());
    let domain = Domain::load(&name, None)?;
    let result = run(&domain, &name, rounds);
    domain.remove_leftover_files();
    result
}

fn run(domain: &Domain, name: &str, rounds: usize) -> Result<()> {
    let tx = Bus::open(domain, "cold-pub", ServiceId::Tool, 0, Stats::new())?;
    let rx = Bus::open(domain, "cold-sub", ServiceId::Tool, 1, Stats::new())?;
    let topic = Topic {
        name: "bench/cold".into(),
        qos: TopicQos::STATE,
    };
    let mut publ = tx.publisher::<VehicleState>(&topic)?;
    let sub = rx.subscriber::<VehicleState>(&topic)?;

    // Raw iceoryx2 under its own file prefix in the same domain name space.
    let mut cfg = iceoryx2::config::Config::default();
    cfg.global.prefix =
        FileName::new(format!("{name}raw").as_bytes()).map_err(|e| anyhow!("prefix: {e:?}"))?;
    let err = |e: &dyn std::fmt::Debug| anyhow!("iceoryx2: {e:?}");
    let ts_node = NodeBuilder::new()
        .config(&cfg)
        .create::<ipc_threadsafe::Service>()
        .map_err(|e| err(&e))?;
    let ts_name: ServiceName = "raw/ts".try_into().map_err(|e| err(&e))?;
    let ts = ts_node
        .service_builder(&ts_name)
        .publish_subscribe::<VehicleState>()
        .open_or_create()
        .map_err(|e| err(&e))?;
    let ts_event = ts_node
        .service_builder(&ts_name)
        .event()
        .open_or_create()
        .map_err(|e| err(&e))?;
    let ts_pub = ts.publisher_builder().create().map_err(|e| err(&e))?;
    let ts_sub = ts.subscriber_builder().create().map_err(|e| err(&e))?;
    let ts_notifier = ts_event.notifier_builder().create().map_err(|e| err(&e))?;
    let _ts_listener = ts_event.listener_builder().create().map_err(|e| err(&e))?;
    let mut buf = vec![0u8; FLUSH_BYTES];
    // skymesh publish, receive; raw ts send, receive.
    let mut t: [Vec<u64>; 4] = Default::default();
    let mut diff: [Vec<i64>; 2] = Default::default();
    let mut seqs = 0u64;
    let s = VehicleState::default();
    for k in 0..rounds {
        let (p, r) = cold(&mut buf, k, || publ.publish(s));
        r?;
        t[0].push(p);
        let (g, r) = cold(&mut buf, k, || sub.try_recv());
        seqs += r?.ok_or_else(|| anyhow!("skymesh: no sample"))?.header.seq;
        t[1].push(g);

        let (p2, (sent, notified)) = cold(&mut buf, k, || {
            (
                ts_pub.send_copy(s).map(drop),
                ts_notifier.notify().map(drop),
            )
        });
        sent.map_err(|e| err(&e))?;
        notified.map_err(|e| err(&e))?;
        t[2].push(p2);
        let (g2, seq) = raw_receive(&ts_sub, &mut buf, k)?;
        seqs += seq;
        t[3].push(g2);
        diff[0].push(p as i64 - p2 as i64);
        diff[1].push(g as i64 - g2 as i64);
    }
    black_box(seqs);
    println!(
        "cold-bench: {rounds} rounds, each operation after a {} MiB flush; ns",
        FLUSH_BYTES >> 20,
    );
    for (i, what) in [
        "skymesh publish",
        "skymesh try_recv",
        "raw ts send + notify",
        "raw ts receive + copy",
    ]
    .iter()
    .enumerate()
    {
        let p = percentiles(&t[i]);
        println!("{what:>22}: p50 {:>7.0}  p99 {:>7.0}", p[0], p[1]);
    }
    for (what, mut d) in ["publish, skymesh − raw ts", "receive, skymesh − raw ts"]
        .into_iter()
        .zip(diff)
    {
        d.sort_unstable();
        println!(
            "{what:>34}, p50 of the per-round difference: {:>6}",
            d[d.len() / 2]
        );
    }
    Ok(())
}
