//! `skymesh-gc`: drive a swarm through skymesh's GroundControl state server.
//!
//! Connects as a GroundControl application would (TCP 8000), sends one command's
//! records, and prints every record that arrives during `--wait`, one per line.
//! `listen-poses` prints the pose broadcast (UDP 6666) instead.

use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use gc_proto::{NetCmdType, Record};
use skymesh_groundcontrol_gateway::cli::{describe, describe_pose, records_for, Cli, Cmd};
use skymesh_groundcontrol_gateway::client::{ClientError, GcClient, PoseListener};
use tokio::time::Instant;

async fn listen_poses(port: u16, count: Option<u64>) -> Result<(), String> {
    let addr = SocketAddr::from(([0, 0, 0, 0], port));
    let mut listener = PoseListener::bind(addr)
        .await
        .map_err(|e| format!("cannot listen on udp {addr}: {e}"))?;
    let mut seen = 0u64;
    while count.is_none_or(|c| seen < c) {
        let got = tokio::select! {
            r = listener.recv(Duration::from_secs(5)) => r.map_err(|e| e.to_string())?,
            _ = tokio::signal::ctrl_c() => return Ok(()),
        };
        match got {
            None => eprintln!("skymesh-gc: no pose datagram for 5 s"),
            Some((from, Ok(poses))) => {
                seen += 1;
                println!("datagram from {from}: {} drones", poses.len());
                for p in &poses {
                    println!("  {}", describe_pose(p));
                }
            }
            Some((from, Err(e))) => println!("datagram from {from}: {e}"),
        }
    }
    Ok(())
}

async fn run(cli: Cli) -> Result<(), String> {
    if !(cli.wait.is_finite() && cli.wait >= 0.0) {
        return Err(format!("--wait {} must be a number of seconds", cli.wait));
    }
    if let Cmd::ListenPoses { port, count } = cli.cmd {
        return listen_poses(port, count).await;
    }
    let records = records_for(&cli.cmd)?;
    let mut client = GcClient::connect(cli.server)
        .await
        .map_err(|e| format!("{e} (is groundcontrol-gateway running?)"))?;
    let ping_sent = Instant::now();
    if cli.cmd == Cmd::Ping {
        client
            .send(&Record::ping_request(1, -1.0, -1.0))
            .await
            .map_err(|e| format!("sending: {e}"))?;
    }
    client
        .send_all(&records)
        .await
        .map_err(|e| format!("sending: {e}"))?;
    let until = Instant::now() + Duration::from_secs_f64(cli.wait);
    loop {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ok(());
        }
        let received = tokio::select! {
            r = client.recv(left) => r,
            _ = tokio::signal::ctrl_c() => return Ok(()),
        };
        match received {
            Ok(None) => {}
            Ok(Some(r)) if r.net_type() == Some(NetCmdType::PingResponse) => println!(
                "{} ({:.3} ms)",
                describe(&r),
                ping_sent.elapsed().as_secs_f64() * 1e3
            ),
            Ok(Some(r)) => println!("{}", describe(&r)),
            Err(ClientError::Closed) => {
                return Err("groundcontrol-gateway closed the connection".to_string())
            }
            Err(e) => return Err(e.to_string()),
        }
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("skymesh-gc: {e}");
            ExitCode::FAILURE
        }
    }
}
