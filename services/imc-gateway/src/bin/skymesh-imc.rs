//! `skymesh-imc`: poke an IMC gateway as Neptus or DUNE would.
//!
//! Sends one IMC message over UDP (or streams `remote-actions` with `--rate`) and
//! prints every message that arrives during `--wait`, one per line; `listen` sends
//! a Heartbeat (so the gateway heartbeats back) and prints until Ctrl-C.

use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use imc_proto::Message;
use skymesh_imc_gateway::cli::{message_for, Cli, Cmd};
use skymesh_imc_gateway::client::{Identity, ImcClient, Received};
use skymesh_imc_gateway::describe::describe;
use tokio::time::Instant;

/// Prints what arrives until `until` (forever with `None`) or Ctrl-C.
async fn print_messages(
    client: &ImcClient,
    until: Option<Instant>,
    all: bool,
) -> Result<(), String> {
    loop {
        let left = until.map_or(Duration::from_secs(3600), |t| {
            t.saturating_duration_since(Instant::now())
        });
        if left.is_zero() {
            return Ok(());
        }
        let received = tokio::select! {
            r = client.recv_datagram(left) => r,
            _ = tokio::signal::ctrl_c() => return Ok(()),
        };
        match received {
            Ok(None) => {}
            Ok(Some(Received {
                from,
                packet: Ok(p),
            })) => {
                if all || !matches!(p.message, Message::Heartbeat | Message::Announce(_)) {
                    println!(
                        "{} (from {from}, src {:#06x}/{})",
                        describe(&p.message),
                        p.header.src,
                        p.header.src_ent
                    );
                }
            }
            Ok(Some(Received {
                from,
                packet: Err(e),
            })) => {
                println!("undecodable datagram from {from}: {e}")
            }
            // ICMP port unreachable from a previous send: nobody listens there.
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                return Err(format!(
                    "{} refused the datagram: is imc-gateway running?",
                    client.target()
                ))
            }
            Err(e) => return Err(e.to_string()),
        }
    }
}

async fn stream(
    client: &ImcClient,
    message: &Message,
    rate: f64,
    duration: f64,
    all: bool,
) -> Result<(), String> {
    if !(rate > 0.0 && rate <= 100.0) {
        return Err(format!("--rate {rate} must be within (0, 100]"));
    }
    if !(duration.is_finite() && duration >= 0.0) {
        return Err(format!("--duration {duration} must be a number of seconds"));
    }
    let end = Instant::now() + Duration::from_secs_f64(duration);
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / rate));
    loop {
        tick.tick().await;
        if Instant::now() >= end {
            return Ok(());
        }
        client
            .send(message)
            .await
            .map_err(|e| format!("sending: {e}"))?;
        print_messages(client, Some(Instant::now() + tick.period()), all).await?;
    }
}

async fn run(cli: Cli) -> Result<(), String> {
    if !(cli.wait.is_finite() && cli.wait >= 0.0) {
        return Err(format!("--wait {} must be a number of seconds", cli.wait));
    }
    let message = message_for(&cli.cmd)?;
    let mut client = ImcClient::connect(cli.to)
        .await
        .map_err(|e| format!("cannot open a UDP socket: {e}"))?;
    client.identity = Identity {
        src: cli.src,
        src_ent: cli.src_ent,
        dst: cli.dst,
        dst_ent: cli.dst_ent,
    };
    let wait_end = || Some(Instant::now() + Duration::from_secs_f64(cli.wait));
    match &cli.cmd {
        Cmd::RemoteActions {
            rate: Some(rate),
            duration,
            ..
        } => {
            stream(&client, &message, *rate, *duration, cli.all).await?;
            print_messages(&client, wait_end(), cli.all).await
        }
        Cmd::Listen => {
            client
                .send(&message)
                .await
                .map_err(|e| format!("sending: {e}"))?;
            print_messages(&client, None, true).await
        }
        _ => {
            client
                .send(&message)
                .await
                .map_err(|e| format!("sending: {e}"))?;
            print_messages(&client, wait_end(), cli.all).await
        }
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("skymesh-imc: {e}");
            ExitCode::FAILURE
        }
    }
}
