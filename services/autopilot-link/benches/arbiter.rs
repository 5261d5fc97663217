//! Arbiter benchmark: prints numbers, asserts nothing.
//!
//! 1. Decision cost: `Arbiter::decide` per command for a GoTo and a velocity
//!    setpoint under a 32-vertex keep-in plus a 32-vertex keep-out (and without a
//!    fence, for comparison), median of several runs.
//! 2. Command sample → MAVLink bytes on the wire: a `VelocityNed` published on the
//!    bus, through an in-process autopilot-link (intake, arbiter, planning, link
//!    writer), to a fake autopilot on 127.0.0.1 TCP built on the mavlink crate that
//!    timestamps each SET_POSITION_TARGET_LOCAL_NED it parses. Both ends read
//!    `CLOCK_MONOTONIC`; one command at a time, 200 per second.
//!
//! `cargo bench -p skymesh-autopilot-link --bench arbiter`

use std::hint::black_box;
use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, ATTITUDE_DATA, HEARTBEAT_DATA,
};
use mavlink::{Connectable, MavConnection, MavHeader, TcpConfig};
use skymesh_autopilot_link::arbiter::geofence::LocalFrame;
use skymesh_autopilot_link::arbiter::{Arbiter, Kinematics, VehicleView};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::{run_with, Detached, RawConfig, Settings};
use skymesh_ipc_types::{
    topics, Command, CommandSource, FenceKind, FlightMode, GeofenceSet, ServiceId, VehicleCommand,
    VehicleStatus,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, CancellationToken, Domain, ServiceConfig, Stats};

const HOME: (f64, f64) = (-35.363261, 149.165230);

fn main() -> anyhow::Result<()> {
    decision_cost()?;
    wire_latency()
}

/// A circle of 32 vertices, `radius_m` around a point `north_m` from home.
fn circle(frame: &LocalFrame, north_m: f64, radius_m: f64) -> Vec<[f64; 2]> {
    let unit = frame.to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    (0..32)
        .map(|i| {
            let a = f64::from(i) * std::f64::consts::TAU / 32.0;
            let (n, e) = (north_m + radius_m * a.cos(), radius_m * a.sin());
            [HOME.0 + n / unit.x * 1e-3, HOME.1 + e / unit.y * 1e-3]
        })
        .collect()
}

fn ns_per_call(iterations: u32, mut f: impl FnMut(u32)) -> f64 {
    let mut runs: Vec<f64> = (0..7)
        .map(|_| {
            let t = Instant::now();
            for i in 0..iterations {
                f(i);
            }
            t.elapsed().as_nanos() as f64 / f64::from(iterations)
        })
        .collect();
    runs.sort_by(f64::total_cmp);
    runs[runs.len() / 2]
}

fn decision_cost() -> anyhow::Result<()> {
    let settings = RawConfig::default().validate()?.arbiter;
    let frame = LocalFrame::new(HOME.0, HOME.1);
    let mut fence = GeofenceSet {
        vehicle_id: 1,
        enabled: 1,
        source: CommandSource::Operator.to_wire(),
        ..Default::default()
    };
    fence.push_polygon(FenceKind::KeepIn, &circle(&frame, 0.0, 300.0));
    fence.push_polygon(FenceKind::KeepOut, &circle(&frame, 100.0, 40.0));
    let view = VehicleView {
        armed: true,
        mode: FlightMode::Guided,
        position: Some(Kinematics {
            lat_deg: HOME.0,
            lon_deg: HOME.1,
            alt_rel_m: 10.0,
            vel_ned_mps: [2.0, 0.0, 0.0],
        }),
    };
    let east_150 = 150.0 / frame.to_local(HOME.0, HOME.1 + 1e-3).y * 1e-3;
    let goto = Command::GoTo {
        lat_deg: HOME.0,
        lon_deg: HOME.1 + east_150,
        alt_rel_m: 20.0,
        yaw_deg: None,
        speed_mps: Some(8.0),
    };
    let cases = [
        ("GoTo (target + path check)", goto),
        (
            "VelocityNed 5 m/s toward the keep-out",
            Command::VelocityNed {
                vel_ned_mps: [5.0, 0.0, 0.0],
                yaw_rate_dps: Some(10.0),
            },
        ),
        (
            "VelocityNed limited (25 m/s, clamped)",
            Command::VelocityNed {
                vel_ned_mps: [25.0, 0.0, -1.0],
                yaw_rate_dps: None,
            },
        ),
    ];
    println!("arbiter decision cost (median of 7 runs of 200 000 decisions)");
    println!("| command | no fence | 32-vertex keep-in + 32-vertex keep-out |");
    println!("|---|---|---|");
    for (name, cmd) in cases {
        let mut row = Vec::new();
        for fenced in [false, true] {
            let mut arbiter = Arbiter::new(settings.clone());
            if fenced {
                arbiter.set_geofence(&fence, 1);
            }
            let mut sample = VehicleCommand::new(1, CommandSource::Operator, 1, &cmd)?;
            let now = 10_000_000_000;
            sample.header.stamp_ns = now;
            let first = arbiter.decide(now, &sample, &view);
            assert!(
                !matches!(
                    first.outcome,
                    skymesh_autopilot_link::arbiter::Outcome::Refused { .. }
                ),
                "{name}: {first:?}"
            );
            row.push(ns_per_call(200_000, |i| {
                sample.command_id = i;
                black_box(arbiter.decide(black_box(now), black_box(&sample), black_box(&view)));
            }));
        }
        println!("| {name} | {:.0} ns | {:.0} ns |", row[0], row[1]);
    }
    Ok(())
}

/// A TCP "autopilot" that sends heartbeats (GUIDED) and ATTITUDE at 10 Hz and
/// reports (arrival ns, vy) for every SET_POSITION_TARGET_LOCAL_NED.
fn fake_autopilot(stop: Arc<AtomicBool>) -> anyhow::Result<(u16, mpsc::Receiver<(u64, f32)>)> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let port = listener.local_addr()?.port();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || -> anyhow::Result<()> {
        let (stream, _) = listener.accept()?;
        stream.set_read_timeout(Some(Duration::from_millis(50)))?;
        stream.set_nodelay(true)?;
        let conn = Arc::new(TcpConfig::from_stream(stream)?.connect::<MavMessage>()?);
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        {
            let (conn, stop) = (conn.clone(), stop.clone());
            std::thread::spawn(move || {
                let mut t = 0;
                while !stop.load(Ordering::Relaxed) {
                    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                        custom_mode: 4,
                        mavtype: MavType::MAV_TYPE_QUADROTOR,
                        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                            | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
                        system_status: MavState::MAV_STATE_ACTIVE,
                        mavlink_version: 3,
                    });
                    let att = MavMessage::ATTITUDE(ATTITUDE_DATA {
                        time_boot_ms: t,
                        ..Default::default()
                    });
                    if conn.send(&header, &hb).is_err() || conn.send(&header, &att).is_err() {
                        return;
                    }
                    t += 100;
                    std::thread::sleep(Duration::from_millis(100));
                }
            });
        }
        while !stop.load(Ordering::Relaxed) {
            match conn.recv() {
                Ok((_, MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp))) => {
                    if tx.send((monotonic_ns(), sp.vy)).is_err() {
                        break;
                    }
                }
                Ok(_) => {}
                Err(mavlink::error::MessageReadError::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(_) => break,
            }
        }
        Ok(())
    });
    Ok((port, rx))
}

fn percentile(sorted: &[u64], p: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i] as f64 / 1000.0
}

fn wire_latency() -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    rt.block_on(async {
        let stop = Arc::new(AtomicBool::new(false));
        let (port, arrivals) = fake_autopilot(stop.clone())?;
        let domain = Domain::load(&format!("aplbench{}", std::process::id()), None)?;
        let stats = Stats::new();
        let bus = Bus::open(&domain, "autopilot-link", ServiceId::AutopilotLink, 0, stats.clone())?;
        let tool = Bus::open(&domain, "bench-tool", ServiceId::Tool, 0, Stats::new())?;
        let mut commands = tool.publisher::<VehicleCommand>(&topics::vehicle_command(1))?;
        let mut status = tool.subscriber::<VehicleStatus>(&topics::vehicle_status(1))?;
        let shutdown = CancellationToken::new();
        let settings = Settings::with_connection(Endpoint::TcpOut {
            host: "127.0.0.1".into(),
            port,
        });
        let link = tokio::spawn(run_with(settings, bus, stats, shutdown.clone(), Detached));
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match status.recv_timeout(left).await? {
                Some(s) if s.is_link_up() => break,
                Some(_) => {}
                None => anyhow::bail!("the link did not come up"),
            }
        }
        const N: u32 = 2000;
        let mut latencies = Vec::with_capacity(N as usize);
        let mut tick = tokio::time::interval(Duration::from_millis(5));
        for i in 0..N {
            tick.tick().await;
            let vy = (i % 1000) as f32 * 0.001;
            let cmd = Command::VelocityNed {
                vel_ned_mps: [1.0, vy, 0.0],
                yaw_rate_dps: None,
            };
            let sample = VehicleCommand::new(1, CommandSource::Operator, i, &cmd)?;
            let sent = monotonic_ns();
            commands.publish(sample)?;
            // The arrival of this very setpoint (a brake from the arbiter would be vy 0 at i 0 only).
            loop {
                let (at, got) = arrivals.recv_timeout(Duration::from_secs(5))?;
                if (got - vy).abs() < 1e-4 {
                    latencies.push(at.saturating_sub(sent));
                    break;
                }
            }
        }
        stop.store(true, Ordering::Relaxed);
        shutdown.cancel();
        link.await??;
        drop((commands, status, tool));
        domain.remove_leftover_files();
        latencies.sort_unstable();
        println!();
        println!("command sample → SET_POSITION_TARGET_LOCAL_NED parsed by the peer ({N} commands, 200/s)");
        println!("| p50 | p99 | min | max |");
        println!("|---|---|---|---|");
        println!(
            "| {:.0} µs | {:.0} µs | {:.0} µs | {:.0} µs |",
            percentile(&latencies, 0.5),
            percentile(&latencies, 0.99),
            percentile(&latencies, 0.0),
            percentile(&latencies, 1.0)
        );
        Ok(())
    })
}
