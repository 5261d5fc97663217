//! DJI `drone_control` published → the MAVLink velocity setpoint carrying it at the
//! vehicle, through the real mesh, at the document's 10 Hz.
//!
//! Runs vehicle-sim, autopilot-link, the embedded mqtt-broker and dji-gateway under
//! the supervisor, with a tap between autopilot-link and vehicle-sim that timestamps
//! every `SET_POSITION_TARGET_*` frame autopilot-link writes. The vehicle hovers at
//! 10 m (taken off over the bus by an operator, who then lets go); the bench, playing
//! the cloud over MQTT, grabs flight authority, enters DRC naming the same broker, and
//! publishes `drone_control` on `drc/down` at 10 Hz with values that change every
//! command. Each command is matched to the first setpoint at the tap whose vertical
//! velocity is its own (`vz = −h`; `h` alternates sign and differs between neighbours,
//! and the vertical axis is not rotated by the vehicle's yaw), and the time from the
//! publish call to that frame is its latency.
//!
//! Split, same run: a bus subscriber in this process on `skymesh/vehicle/1/command`
//! sees each command as the gateway publishes it (`bus`: publish → gateway →
//! iceoryx2 → subscriber wakes), so `drc − bus` is roughly autopilot-link's share
//! (arbiter, MAVLink encode, TCP to the tap) — where the time goes.
//!
//! The baseline, in the same run and for the very same messages: a plain MQTT
//! subscriber on `drc/down` on the same broker, the time from the publish call to its
//! receipt (the broker hop every DRC command pays before the gateway sees it).
//!
//! `cargo run --release -p skymesh-e2e --bin dji-bench -- --commands 300 [--realtime 20] [--vision]`
//!
//! `--vision` adds the camera and the vision pipeline to the mesh (the load a
//! companion computer carries in flight); `--realtime P` runs the control path
//! `SCHED_FIFO` on CPU 1 as deploy/skymesh.toml does (broker and gateway at P,
//! autopilot-link at P + 10; `--pin none` or `--pin N` for no or another CPU) and
//! the bench's own threads at P + 10 on the same CPU (`bench::ControlPath`).

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink_frame::FrameParser;
use rumqttc::{AsyncClient, Event, EventLoop, MqttOptions, Packet, QoS};
use serde_json::{json, Value};
use skymesh_e2e::bench::{arg, bench_thread_realtime, percentile, start_tapped_mesh, ControlPath};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{topics, Command, ServiceId, VehicleCommand};
use skymesh_runtime::{Bus, Stats};
use tokio::sync::mpsc as tmpsc;

/// Commands sent before the measured ones (the first switches the link, the stream
/// and the vehicle's controller into steady state) and left out of the numbers.
const WARMUP: usize = 10;

/// One velocity setpoint autopilot-link wrote toward the vehicle: when, and its NED velocity.
#[derive(Debug, Clone, Copy)]
struct Seen {
    at: Instant,
    vel: [f32; 3],
}

/// Reports every SET_POSITION_TARGET_* that autopilot-link sends, with its velocity.
fn scan_setpoints(parser: &mut FrameParser, now: Instant, out: &mpsc::Sender<Seen>) {
    while let Some(frame) = parser.next_frame() {
        if !matches!(frame.message_id(), 84 | 86) {
            continue;
        }
        let vel = match frame.decode() {
            Ok(MavMessage::SET_POSITION_TARGET_LOCAL_NED(m)) => [m.vx, m.vy, m.vz],
            Ok(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(m)) => [m.vx, m.vy, m.vz],
            _ => continue,
        };
        let _ = out.send(Seen { at: now, vel });
    }
}

/// A bus subscriber on vehicle 1's command topic, on its own thread: every
/// `VelocityNed` with the time it was received, until `stop`.
fn command_watch(mesh: &Mesh, stop: Arc<AtomicBool>) -> Result<mpsc::Receiver<Seen>> {
    let domain = mesh.ipc_domain()?;
    let (tx, rx) = mpsc::channel();
    let (ready_tx, ready_rx) = mpsc::channel();
    std::thread::spawn(move || {
        bench_thread_realtime();
        let run = || -> Result<()> {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            rt.block_on(async {
                let bus = Bus::open(&domain, "dji-bench-split", ServiceId::Tool, 0, Stats::new())?;
                let mut cmds = bus.subscriber::<VehicleCommand>(&topics::vehicle_command(1))?;
                let _ = ready_tx.send(());
                while !stop.load(Ordering::Relaxed) {
                    if let Some(c) = cmds.recv_timeout(Duration::from_millis(200)).await? {
                        let at = Instant::now();
                        if let Ok(Command::VelocityNed { vel_ned_mps, .. }) = c.command() {
                            let _ = tx.send(Seen {
                                at,
                                vel: vel_ned_mps,
                            });
                        }
                    }
                }
                anyhow::Ok(())
            })
        };
        if let Err(e) = run() {
            eprintln!("command watch: {e:#}");
        }
    });
    ready_rx
        .recv_timeout(Duration::from_secs(10))
        .context("command watch did not start")?;
    Ok(rx)
}

/// One MQTT connection whose received publishes (topic, payload, arrival) go to a channel.
struct Mqtt {
    client: AsyncClient,
    rx: tmpsc::UnboundedReceiver<(String, Vec<u8>, Instant)>,
}

impl Mqtt {
    async fn connect(id: &str, host: &str, port: u16, subscribe: &[String]) -> Result<Mqtt> {
        let mut opts = MqttOptions::new(id, host, port);
        // Longer than a run: a PINGREQ mid-run stalls one receipt (seen: one 11 ms outlier at 30 s).
        opts.set_keep_alive(Duration::from_secs(120));
        let (client, mut eventloop) = AsyncClient::new(opts, 1024);
        let mut net = eventloop.network_options();
        net.set_tcp_nodelay(true);
        eventloop.set_network_options(net);
        let (tx, rx) = tmpsc::unbounded_channel();
        let (ready_tx, mut ready_rx) = tmpsc::unbounded_channel();
        for t in subscribe {
            client.subscribe(t.clone(), QoS::AtLeastOnce).await?;
        }
        tokio::spawn(drive(eventloop, tx, ready_tx, subscribe.len()));
        tokio::time::timeout(Duration::from_secs(10), ready_rx.recv())
            .await
            .with_context(|| format!("{id}: no CONNACK/SUBACK from {host}:{port}"))?
            .context("event loop ended")?;
        Ok(Mqtt { client, rx })
    }

    async fn publish(&self, topic: &str, payload: Vec<u8>) -> Result<()> {
        self.client
            .publish(topic, QoS::AtLeastOnce, false, payload)
            .await?;
        Ok(())
    }

    /// The next message on `topic` whose JSON satisfies `f`, within `timeout`.
    async fn expect(
        &mut self,
        topic: &str,
        timeout: Duration,
        f: impl Fn(&Value) -> bool,
    ) -> Result<Value> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let (t, payload, _) = tokio::time::timeout_at(deadline, self.rx.recv())
                .await
                .with_context(|| format!("nothing matching on {topic} within {timeout:?}"))?
                .context("connection closed")?;
            if t == topic {
                if let Ok(v) = serde_json::from_slice::<Value>(&payload) {
                    if f(&v) {
                        return Ok(v);
                    }
                }
            }
        }
    }
}

/// Polls the event loop forever; reports readiness once the subscriptions are acknowledged.
async fn drive(
    mut eventloop: EventLoop,
    tx: tmpsc::UnboundedSender<(String, Vec<u8>, Instant)>,
    ready: tmpsc::UnboundedSender<()>,
    subscriptions: usize,
) {
    let mut subacks = 0;
    if subscriptions == 0 {
        let _ = ready.send(());
    }
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let at = Instant::now();
                if tx.send((p.topic.clone(), p.payload.to_vec(), at)).is_err() {
                    return;
                }
            }
            Ok(Event::Incoming(Packet::SubAck(_))) => {
                subacks += 1;
                if subacks == subscriptions {
                    let _ = ready.send(());
                }
            }
            Ok(_) => {}
            Err(_) if tx.is_closed() => return,
            Err(e) => {
                eprintln!("mqtt: {e}");
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
    }
}

fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// A `services` call; returns the reply's `data.result`.
async fn call(cloud: &mut Mqtt, sn: &str, method: &str, data: Value) -> Result<i64> {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    let tid = format!("bench-{method}-{}", NEXT.fetch_add(1, Ordering::Relaxed));
    let body =
        json!({"tid": tid, "bid": tid, "timestamp": now_ms(), "method": method, "data": data});
    cloud
        .publish(
            &format!("thing/product/{sn}/services"),
            body.to_string().into_bytes(),
        )
        .await?;
    let reply = cloud
        .expect(
            &format!("thing/product/{sn}/services_reply"),
            Duration::from_secs(15),
            |v| v["tid"] == tid.as_str(),
        )
        .await
        .with_context(|| format!("no services_reply to {method}"))?;
    reply["data"]["result"]
        .as_i64()
        .with_context(|| format!("{method}: reply without data.result: {reply}"))
}

/// Command `i`'s sticks: forward and left speeds sweep slowly (the vehicle wanders a few
/// metres), `h` alternates sign with a magnitude that differs between neighbours, so
/// `vz = −h` identifies the command at the tap and the altitude stays put.
fn sticks(i: usize) -> (f64, f64, f64) {
    let phase = i as f64 * std::f64::consts::TAU;
    let y = 2.0 * (phase / 50.0).sin();
    let x = 0.5 * (phase / 70.0).cos();
    let sign = if i.is_multiple_of(2) { 1.0 } else { -1.0 };
    let h = sign * (0.30 + (i % 13) as f64 * 0.05);
    (x, y, h)
}

fn report(name: &str, mut ms: Vec<f64>, base_p50: Option<f64>) -> f64 {
    ms.sort_by(f64::total_cmp);
    let p50 = percentile(&ms, 0.5);
    let ratio = base_p50
        .map(|b| format!("  p50/baseline={:.1}x", p50 / b))
        .unwrap_or_default();
    println!(
        "{name:<10} n={:<4} p50={p50:8.3} ms  p99={:8.3} ms  p999={:8.3} ms  max={:8.3} ms{ratio}",
        ms.len(),
        percentile(&ms, 0.99),
        percentile(&ms, 0.999),
        percentile(&ms, 1.0),
    );
    p50
}

/// Where the slowest commands' time went. `split:gw` is each command's bus stamp
/// minus its baseline stamp: what the gateway and the bus hop took beyond the
/// broker's delivery to a plain MQTT client (signed: the broker serves the two
/// subscribers one after the other). Then the slowest 1 % (at least three) by
/// total, each split into the broker's delivery (the baseline's stamp), the
/// gateway's share and autopilot-link's.
fn tail_report(mut parts: Vec<[f64; 4]>) {
    if parts.is_empty() {
        return;
    }
    report("split:gw", parts.iter().map(|p| p[2]).collect(), None);
    parts.sort_by(|a, b| b[0].total_cmp(&a[0]));
    let n = (parts.len() / 100).max(3).min(parts.len());
    let slowest: Vec<String> = parts[..n]
        .iter()
        .map(|p| format!("{:.2} = {:.2} + {:.2} + {:.2}", p[0], p[1], p[2], p[3]))
        .collect();
    println!(
        "slowest {n} (ms: total = broker to a client + gateway and bus + autopilot-link): {}",
        slowest.join(", ")
    );
}

async fn bench(
    mesh: &Mesh,
    seen_rx: mpsc::Receiver<Seen>,
    bus_rx: mpsc::Receiver<Seen>,
    commands: usize,
) -> Result<()> {
    skymesh_e2e::bench::take_off(mesh, 10.0).await?;
    let (host, port) = (mesh.mqtt_addr.ip().to_string(), mesh.mqtt_addr.port());
    let sn = mesh.gateway_sn.clone();
    let topic = |suffix: &str| format!("thing/product/{sn}/{suffix}");

    let mut cloud = Mqtt::connect("bench-cloud", &host, port, &[topic("services_reply")]).await?;
    let r = call(&mut cloud, &sn, "flight_authority_grab", json!({})).await?;
    if r != 0 {
        bail!("flight_authority_grab: result {r}");
    }
    let mut drc = Mqtt::connect("bench-drc", &host, port, &[topic("drc/up")]).await?;
    // The broker delivers to subscribers in subscription order: `--baseline-last 1`
    // subscribes the baseline after the gateway (it is served second), the default
    // before it.
    let baseline_last = arg("--baseline-last", 0) != 0;
    let mut baseline = if baseline_last {
        None
    } else {
        Some(Mqtt::connect("bench-baseline", &host, port, &[topic("drc/down")]).await?)
    };
    let enter = json!({
        "mqtt_broker": {
            "address": format!("{host}:{port}"), "client_id": format!("drc-{sn}"),
            "username": "", "password": "", "expire_time": now_ms() / 1000 + 3600,
            "enable_tls": false,
        },
        "osd_frequency": 1, "hsi_frequency": 1,
    });
    let r = call(&mut cloud, &sn, "drc_mode_enter", enter).await?;
    if r != 0 {
        bail!("drc_mode_enter: result {r}");
    }
    let down = topic("drc/down");
    let up = topic("drc/up");
    let hb = json!({"method": "heart_beat", "data": {"seq": 0, "timestamp": now_ms()}});
    drc.publish(&down, hb.to_string().into_bytes()).await?;
    drc.expect(&up, Duration::from_secs(5), |v| v["method"] == "heart_beat")
        .await
        .context("no heart_beat echo: DRC link not up")?;
    let mut baseline = match baseline.take() {
        Some(b) => b,
        None => Mqtt::connect("bench-baseline", &host, port, &[topic("drc/down")]).await?,
    };
    while seen_rx.try_recv().is_ok() {}
    while bus_rx.try_recv().is_ok() {}

    // 10 Hz, each publish stamped just before the call.
    let total = WARMUP + commands;
    let mut sent: Vec<(Instant, f64)> = Vec::with_capacity(total);
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    for i in 0..total {
        tick.tick().await;
        let (x, y, h) = sticks(i);
        let body = json!({"method": "drone_control",
                          "data": {"seq": i, "x": x, "y": y, "h": h, "w": 0.0}});
        let payload = body.to_string().into_bytes();
        let t0 = Instant::now();
        drc.publish(&down, payload).await?;
        sent.push((t0, h));
        if i % 100 == 99 {
            let hb = json!({"method": "heart_beat", "data": {"seq": i, "timestamp": now_ms()}});
            drc.publish(&down, hb.to_string().into_bytes()).await?;
        }
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    let seen: Vec<Seen> = seen_rx.try_iter().collect();
    let on_bus: Vec<Seen> = bus_rx.try_iter().collect();

    // The baseline subscriber's receipts, by seq.
    let mut base_at: HashMap<u64, Instant> = HashMap::new();
    while let Ok((t, payload, at)) = baseline.rx.try_recv() {
        if t != down {
            continue;
        }
        if let Ok(v) = serde_json::from_slice::<Value>(&payload) {
            if let (Some("drone_control"), Some(seq)) =
                (v["method"].as_str(), v["data"]["seq"].as_u64())
            {
                base_at.entry(seq).or_insert(at);
            }
        }
    }
    // The gateway's answers on drc/up.
    let mut results: HashMap<i64, usize> = HashMap::new();
    while let Ok((t, payload, _)) = drc.rx.try_recv() {
        if t != up {
            continue;
        }
        if let Ok(v) = serde_json::from_slice::<Value>(&payload) {
            if v["method"] == "drone_control" {
                *results
                    .entry(v["data"]["result"].as_i64().unwrap_or(-1))
                    .or_default() += 1;
            }
        }
    }

    let (mut drc_ms, mut base_ms, mut unmatched) = (Vec::new(), Vec::new(), 0usize);
    let (mut bus_ms, mut link_ms) = (Vec::new(), Vec::new());
    // Per command with all four stamps: (total, baseline, bus − baseline, link), ms.
    let mut parts: Vec<[f64; 4]> = Vec::new();
    for (i, &(t0, h)) in sent.iter().enumerate().skip(WARMUP) {
        let end = sent.get(i + 1).map(|s| s.0 + Duration::from_secs(1));
        let want = -h as f32;
        let find = |list: &[Seen]| {
            list.iter()
                .find(|s| {
                    s.at >= t0 && end.is_none_or(|e| s.at < e) && (s.vel[2] - want).abs() < 1e-3
                })
                .copied()
        };
        let hit = find(&seen);
        match hit {
            Some(s) => drc_ms.push((s.at - t0).as_secs_f64() * 1e3),
            None => unmatched += 1,
        }
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let base = base_at.get(&(i as u64)).map(|at| ms(*at - t0));
        if let Some(b) = base {
            base_ms.push(b);
        }
        if let Some(b) = find(&on_bus) {
            let bus = ms(b.at - t0);
            bus_ms.push(bus);
            if let Some(s) = hit {
                let link = ms(s.at.saturating_duration_since(b.at));
                link_ms.push(link);
                if let Some(base) = base {
                    parts.push([ms(s.at - t0), base, bus - base, link]);
                }
            }
        }
    }

    let r = call(&mut cloud, &sn, "drc_mode_exit", json!({})).await?;
    println!(
        "dji-bench: {commands} drone_control at 10 Hz after {WARMUP} warm-up \
         (publish on drc/down → SET_POSITION_TARGET_* with its velocity at the vehicle's port); \
         baseline subscribed {} the gateway",
        if baseline_last { "after" } else { "before" }
    );
    let base_p50 = report("baseline", base_ms, None);
    report("drc", drc_ms, Some(base_p50));
    report("split:bus", bus_ms, Some(base_p50));
    report("split:link", link_ms, None);
    tail_report(parts);
    let mut results: Vec<_> = results.into_iter().collect();
    results.sort();
    println!(
        "unmatched (no setpoint with its velocity): {unmatched}; drone_control results \
         (result: count) {results:?}; drc_mode_exit result {r}"
    );
    Ok(())
}

fn main() -> Result<()> {
    let commands = arg("--commands", 300) as usize;
    if commands < 1 {
        bail!("--commands must be at least 1");
    }
    let control = ControlPath::from_args(&[
        ("mqtt-broker", false),
        ("dji-gateway", false),
        ("autopilot-link", true),
    ])?;
    println!("dji-bench: {}", control.describe);
    let (opts, services) = control.mesh(
        MeshOptions {
            dji: true,
            attitude_hz: 25.0,
            ..Default::default()
        },
        &[
            "vehicle-sim",
            "autopilot-link",
            "mqtt-broker",
            "dji-gateway",
        ],
    );
    let (seen_tx, seen_rx) = mpsc::channel();
    let mut mesh = start_tapped_mesh(opts, &services, move |parser, now| {
        scan_setpoints(parser, now, &seen_tx)
    })?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .on_thread_start(bench_thread_realtime)
        .enable_all()
        .build()?;
    let stop_watch = Arc::new(AtomicBool::new(false));
    let bus_rx = command_watch(&mesh, stop_watch.clone())?;
    let outcome = rt.block_on(bench(&mesh, seen_rx, bus_rx, commands));
    stop_watch.store(true, Ordering::Relaxed);
    // The MQTT tasks end with the runtime, before the broker goes away.
    rt.shutdown_timeout(Duration::from_secs(1));
    if outcome.is_err() {
        eprintln!("{}", mesh.output());
    }
    outcome?;
    mesh.stop(Duration::from_secs(10))?;
    Ok(())
}
