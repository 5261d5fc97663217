//! Per-tick cost of the swarm queue's processing at 10, 100 and 250 drones.
//!
//! `cargo run --release -p skymesh-swarm-queue --bin swarm-bench [ticks]`
//!
//! The pure core (`Swarm`) against the kinematic fake fleet, 30 Hz ticks of
//! simulated time. Timed per tick: what the service does with the core in one tick
//! — hand it every drone's newest state and status and the acknowledgements of the
//! previous tick's commands, `tick`, take the outputs, build the `SwarmState` — but
//! not the fleet's simulation and not the bus (publishing is measured by the
//! runtime's own benchmarks). Scenarios, all in the same run:
//!
//! - `idle` (baseline): every drone on the ground, nothing queued;
//! - `hover` (baseline): every drone flying, nothing queued;
//! - `waypoint`: every drone flying a waypoint with nine more queued behind it;
//! - `animation`: every drone playing a looping animation (positions streamed at
//!   10 Hz, colours every tick);
//! - `follow`: a new `WAYPOINT_FOLLOW` for every drone every tick (the gateway's
//!   worst case), handling included.
//!
//! Prints mean, 99th percentile and maximum per tick, and the mean per drone. No
//! assertions: numbers for the record.
//!
//! A second table measures the service's whole tick with the real bus (iceoryx2
//! shared memory, a domain of its own): every drone's state and status published by
//! the fleet on its topics (untimed), then timed: drain every drone's three
//! subscribers, step the queue, publish its vehicle commands and the `SwarmState`.
//! The commands reach the fleet directly (no autopilot-link subscribers: about 31
//! file descriptors per port set, see the service's docs), so delivery to a
//! subscriber is not in the numbers.

use std::path::Path;
use std::time::Instant;

use skymesh_ipc_types::{
    CommandAck, SwarmCommand, SwarmCommandKind, SwarmState, VehicleCommand, VehicleState,
    VehicleStatus, ALL_DRONES,
};
use skymesh_runtime::{Bus, Domain, Publisher, Stats};
use skymesh_swarm_queue::anim::{AnimLibrary, Animation, Keyframe};
use skymesh_swarm_queue::fake::FakeFleet;
use skymesh_swarm_queue::ipc::Ports;
use skymesh_swarm_queue::metrics::Metrics;
use skymesh_swarm_queue::{RawConfig, Swarm};

const TICK_NS: u64 = 33_333_333;

fn settings(n: usize) -> skymesh_swarm_queue::Settings {
    let text = format!(
        "site_origin = {{ lat_deg = -35.363261, lon_deg = 149.165230, alt_msl_m = 584.0 }}\n\
         drones = {{ first_id = 1, count = {n}, first_vehicle_id = 1 }}\n\
         hardware_drone = 1\nqueue_capacity = 256\n"
    );
    let raw: RawConfig = toml::from_str(&text).expect("bench config");
    raw.validate_in(Path::new("/nonexistent"))
        .expect("bench settings")
}

/// A 1.5 m circle around (x0, 0) at 3 m, 8 s a lap, 64 keyframes, colour cycling.
fn circle(x0: f32) -> Animation {
    let frames = (0..=64)
        .map(|i| {
            let a = i as f32 / 64.0 * std::f32::consts::TAU;
            Keyframe {
                time_s: f64::from(i) * 0.125,
                pos: [x0 + 1.5 * a.cos(), 1.5 * a.sin(), 3.0],
                yaw_deg: a.to_degrees() - 180.0 + 90.0,
                rgb: [(a.sin() + 1.0) / 2.0, (a.cos() + 1.0) / 2.0, 0.5],
            }
        })
        .collect();
    Animation::new(frames).expect("circle")
}

struct Bench {
    swarm: Swarm,
    fleet: FakeFleet,
    now: u64,
    acks: Vec<(usize, CommandAck)>,
    states: Vec<(VehicleState, VehicleStatus)>,
    state: Box<SwarmState>,
    request: u32,
}

impl Bench {
    fn new(n: usize) -> Bench {
        let cfg = settings(n);
        let ids: Vec<u16> = cfg.drones.iter().map(|d| d.id).collect();
        let mut swarm = Swarm::new(
            cfg,
            AnimLibrary::new("/nonexistent"),
            Metrics::new(&Stats::new(), &ids),
            1_000_000_000_000,
        );
        for (i, id) in ids.iter().enumerate() {
            swarm.anims_mut().insert(*id, circle(i as f32 * 4.0));
        }
        let fleet = FakeFleet::for_swarm(&swarm, 4.0);
        Bench {
            swarm,
            fleet,
            now: 1_000_000_000_000,
            acks: Vec::new(),
            states: Vec::new(),
            state: Box::new(SwarmState::default()),
            request: 0,
        }
    }

    fn command(&mut self, drone: u16, kind: SwarmCommandKind, set: impl FnOnce(&mut SwarmCommand)) {
        self.request += 1;
        let mut c = SwarmCommand {
            request_id: self.request,
            drone,
            kind: kind.to_wire(),
            ..SwarmCommand::default()
        };
        set(&mut c);
        self.swarm.handle_command(&c, self.now);
    }

    /// One tick; returns the nanoseconds spent in the queue.
    fn tick(&mut self, mut extra: impl FnMut(&mut Bench)) -> u64 {
        self.now += TICK_NS;
        // Untimed: the vehicles move and answer.
        self.states.clear();
        for v in self.fleet.vehicles.iter_mut() {
            v.step(TICK_NS as f64 / 1e9);
        }
        for v in &self.fleet.vehicles {
            self.states.push((v.state(self.now), v.status()));
        }
        let t = Instant::now();
        extra(self);
        for (i, (s, st)) in self.states.iter().enumerate() {
            self.swarm.handle_state(i, s, self.now);
            self.swarm.handle_status(i, st, self.now);
        }
        for (i, a) in self.acks.drain(..) {
            self.swarm.handle_ack(i, &a, self.now);
        }
        self.swarm.tick(self.now);
        let out = self.swarm.take_outputs();
        while self.swarm.pop_reply().is_some() {}
        self.swarm.fill_state(self.now, &mut self.state);
        let ns = t.elapsed().as_nanos() as u64;
        // Untimed: the commands reach the vehicles.
        self.answer(&out.commands);
        ns
    }

    fn answer(&mut self, commands: &[VehicleCommand]) {
        for c in commands {
            if let Some(i) = self.swarm.index_of_vehicle(c.vehicle_id) {
                if let Some(a) = self.fleet.vehicles[i].handle(c) {
                    self.acks.push((i, a));
                }
            }
        }
    }

    fn settle(&mut self, secs: f64) {
        for _ in 0..(secs * 30.0) as usize {
            self.tick(|_| {});
        }
    }

    fn take_off(&mut self) {
        self.command(ALL_DRONES, SwarmCommandKind::ExtGoExternal, |_| {});
        let out = self.swarm.take_outputs();
        self.answer(&out.commands);
        self.settle(3.0);
    }
}

#[derive(Debug)]
struct Stat {
    mean_us: f64,
    p99_us: f64,
    max_us: f64,
}

fn measure(b: &mut Bench, ticks: usize, mut extra: impl FnMut(&mut Bench)) -> Stat {
    let mut ns: Vec<u64> = (0..ticks).map(|_| b.tick(&mut extra)).collect();
    ns.sort_unstable();
    let mean = ns.iter().sum::<u64>() as f64 / ns.len() as f64;
    Stat {
        mean_us: mean / 1e3,
        p99_us: ns[(ns.len() * 99 / 100).min(ns.len() - 1)] as f64 / 1e3,
        max_us: *ns.last().unwrap_or(&0) as f64 / 1e3,
    }
}

fn report(n: usize, scenario: &str, s: &Stat) {
    println!(
        "{n:>5} {scenario:<10} {:>10.1} {:>10.1} {:>10.1} {:>12.3} {:>9.2}",
        s.mean_us,
        s.p99_us,
        s.max_us,
        s.mean_us / n as f64,
        s.mean_us / 33_333.3 * 100.0,
    );
}

/// The fleet's side of the bus: a state and a status publisher per vehicle.
struct Autopilots {
    state: Vec<Publisher<VehicleState>>,
    status: Vec<Publisher<VehicleStatus>>,
}

fn bus_tick(b: &mut Bench, ports: &mut Ports, ap: &mut Autopilots) -> u64 {
    b.now += TICK_NS;
    for v in b.fleet.vehicles.iter_mut() {
        v.step(TICK_NS as f64 / 1e9);
    }
    for (i, v) in b.fleet.vehicles.iter().enumerate() {
        ap.state[i].publish(v.state(b.now)).expect("publish state");
        ap.status[i].publish(v.status()).expect("publish status");
    }
    for (i, a) in b.acks.drain(..) {
        b.swarm.handle_ack(i, &a, b.now);
    }
    let t = Instant::now();
    for (i, d) in ports.drones.iter().enumerate() {
        if let Some(s) = d.state.latest().expect("drain") {
            b.swarm.handle_state(i, &s, b.now);
        }
        if let Some(s) = d.status.latest().expect("drain") {
            b.swarm.handle_status(i, &s, b.now);
        }
        while let Some(a) = d.acks.try_recv().expect("drain") {
            b.swarm.handle_ack(i, &a, b.now);
        }
    }
    b.swarm.tick(b.now);
    let out = b.swarm.take_outputs();
    for c in &out.commands {
        if let Some(i) = b.swarm.index_of_vehicle(c.vehicle_id) {
            ports.drones[i]
                .commands
                .publish(*c)
                .expect("publish command");
        }
    }
    while let Some(r) = b.swarm.pop_reply() {
        ports.replies.publish(r).expect("publish reply");
    }
    b.swarm.fill_state(b.now, &mut b.state);
    ports.state.publish(*b.state).expect("publish state");
    let ns = t.elapsed().as_nanos() as u64;
    b.answer(&out.commands);
    ns
}

fn with_bus(ticks: usize) {
    if let Err(e) = skymesh_swarm_queue::fdlimit::raise_nofile_limit() {
        println!("cannot raise the open file limit: {e}");
    }
    let domain = Domain::load(&format!("swb{}", std::process::id()), None).expect("domain");
    println!();
    println!("with the bus: drain 3 subscribers per drone, tick, publish commands and state");
    println!(
        "{:>5} {:<10} {:>10} {:>10} {:>10} {:>12} {:>9}",
        "drones", "scenario", "mean µs", "p99 µs", "max µs", "µs/drone", "% of tick"
    );
    for n in [10usize, 100, 250] {
        let mut b = Bench::new(n);
        let queue_bus = Bus::open(
            &domain,
            "swarm-queue",
            skymesh_ipc_types::ServiceId::SwarmQueue,
            0,
            Stats::new(),
        )
        .expect("bus");
        let fleet_bus = Bus::open(
            &domain,
            "fleet",
            skymesh_ipc_types::ServiceId::Tool,
            0,
            Stats::new(),
        )
        .expect("bus");
        let mut ports = Ports::open(&queue_bus, b.swarm.settings()).expect("ports");
        let mut ap = Autopilots {
            state: b
                .fleet
                .vehicles
                .iter()
                .map(|v| {
                    fleet_bus
                        .publisher(&skymesh_ipc_types::topics::vehicle_state(v.vehicle_id))
                        .expect("pub")
                })
                .collect(),
            status: b
                .fleet
                .vehicles
                .iter()
                .map(|v| {
                    fleet_bus
                        .publisher(&skymesh_ipc_types::topics::vehicle_status(v.vehicle_id))
                        .expect("pub")
                })
                .collect(),
        };
        let run = |b: &mut Bench, ports: &mut Ports, ap: &mut Autopilots, name: &str| {
            let mut ns: Vec<u64> = (0..ticks).map(|_| bus_tick(b, ports, ap)).collect();
            ns.sort_unstable();
            let mean = ns.iter().sum::<u64>() as f64 / ns.len() as f64;
            report(
                n,
                name,
                &Stat {
                    mean_us: mean / 1e3,
                    p99_us: ns[(ns.len() * 99 / 100).min(ns.len() - 1)] as f64 / 1e3,
                    max_us: *ns.last().unwrap_or(&0) as f64 / 1e3,
                },
            );
        };
        run(&mut b, &mut ports, &mut ap, "idle");
        b.command(ALL_DRONES, SwarmCommandKind::ExtGoExternal, |_| {});
        let out = b.swarm.take_outputs();
        b.answer(&out.commands);
        for _ in 0..90 {
            bus_tick(&mut b, &mut ports, &mut ap);
        }
        b.command(ALL_DRONES, SwarmCommandKind::ExtPlaybackAnim, |c| {
            c.int2 = -1;
            c.f[..4].copy_from_slice(&[1.0, 1.0, 1.0, 1.0]);
        });
        run(&mut b, &mut ports, &mut ap, "animation");
    }
}

fn main() {
    let ticks: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(900);
    println!(
        "swarm-queue tick cost, {ticks} ticks of 1/30 s per scenario (release build recommended)"
    );
    println!(
        "{:>5} {:<10} {:>10} {:>10} {:>10} {:>12} {:>9}",
        "drones", "scenario", "mean µs", "p99 µs", "max µs", "µs/drone", "% of tick"
    );
    for n in [10usize, 100, 250] {
        // Baseline: on the ground, idle.
        let mut b = Bench::new(n);
        b.settle(0.5);
        report(n, "idle", &measure(&mut b, ticks, |_| {}));

        b.take_off();
        report(n, "hover", &measure(&mut b, ticks, |_| {}));

        // Waypoints: far enough to keep flying for the whole measurement, nine queued.
        for k in 0..10 {
            let x = 400.0 + k as f32;
            b.command(ALL_DRONES, SwarmCommandKind::ExtWaypoint, |c| {
                c.f[..4].copy_from_slice(&[x, 0.0, 5.0, 1.0])
            });
        }
        report(n, "waypoint", &measure(&mut b, ticks, |_| {}));
        b.command(ALL_DRONES, SwarmCommandKind::ExtHalt, |_| {});
        b.settle(0.2);

        b.command(ALL_DRONES, SwarmCommandKind::ExtPlaybackAnim, |c| {
            c.int2 = -1;
            c.f[..4].copy_from_slice(&[1.0, 1.0, 1.0, 1.0]);
        });
        report(n, "animation", &measure(&mut b, ticks, |_| {}));
        b.command(ALL_DRONES, SwarmCommandKind::ExtHalt, |_| {});
        b.settle(0.2);

        let mut k = 0u32;
        report(
            n,
            "follow",
            &measure(&mut b, ticks, |b| {
                k += 1;
                let y = (k % 100) as f32 * 0.05;
                for d in 1..=n as u16 {
                    b.command(d, SwarmCommandKind::ExtWaypointFollow, |c| {
                        c.f[..3].copy_from_slice(&[f32::from(d) * 4.0, y, 3.0])
                    });
                }
            }),
        );
    }
    with_bus(ticks);
}
