//! `skymesh-solo`: fly Solo shots without the phone app.
//!
//! Connects to solo-gateway as the app would (TCP 5507), sends one command, and
//! prints every message that arrives during `--wait`, one per line. `follow` also
//! streams positions to the follow stream (UDP 14558) and `listen` stays connected;
//! `button` presses a controller button by publishing a `ButtonEvent` on the bus.

use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use skymesh_ipc_types::{topics, Button, ButtonEvent, ButtonEventKind, ServiceId};
use skymesh_runtime::{Bus, Domain, Stats};
use skymesh_solo_gateway::cli::{message_for, moved, named, Cli, Cmd};
use skymesh_solo_gateway::client::{AppClient, ClientError, FollowStreamer};
use skymesh_solo_gateway::describe::describe;
use solo_proto::{Location, SoloMessage};
use tokio::time::Instant;

/// Prints what arrives until `until` (forever with `None`) or Ctrl-C (then `Ok(true)`).
async fn print_messages(client: &mut AppClient, until: Option<Instant>) -> Result<bool, String> {
    loop {
        let left = until.map_or(Duration::from_secs(3600), |t| {
            t.saturating_duration_since(Instant::now())
        });
        if left.is_zero() {
            return Ok(false);
        }
        let received = tokio::select! {
            r = client.recv_frame(left) => r,
            _ = tokio::signal::ctrl_c() => return Ok(true),
        };
        match received {
            Ok(None) => {}
            Ok(Some((_, Ok(SoloMessage::SecondPhoneNotification)))) => {
                return Err("another phone is connected to solo-gateway (SOLO_SECOND_PHONE_NOTIFICATION): only one app at a time".into())
            }
            Ok(Some((_, Ok(m)))) => println!("{}", describe(&m)),
            Ok(Some((frame, Err(e)))) => {
                println!("type {} ({} bytes): {e}", frame.msg_type, frame.value.len())
            }
            Err(ClientError::Closed) => {
                let why = client.closed_reason().unwrap_or("closed").to_string();
                return Err(format!("solo-gateway closed the connection: {why}"));
            }
            Err(e) => return Err(e.to_string()),
        }
    }
}

/// Streams LOCATION datagrams, printing what arrives on TCP meanwhile.
async fn follow(client: &mut AppClient, cli: &Cli) -> Result<(), String> {
    let Cmd::Follow {
        lat,
        lon,
        alt,
        rate,
        velocity_north,
        velocity_east,
        duration,
        udp,
    } = &cli.cmd
    else {
        return Ok(());
    };
    if !(*rate > 0.0 && *rate <= 100.0) {
        return Err(format!("--rate {rate} must be within (0, 100]"));
    }
    let target = udp.unwrap_or_else(|| SocketAddr::new(cli.addr.ip(), 14558));
    let streamer = FollowStreamer::bind(client.local_addr().ip(), target)
        .await
        .map_err(|e| format!("cannot open the follow stream to {target}: {e}"))?;
    let started = Instant::now();
    let end = duration.map(|d| started + Duration::from_secs_f64(d.max(0.0)));
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / rate));
    let start = Location {
        lat_deg: *lat,
        lon_deg: *lon,
        alt_m: *alt,
    };
    loop {
        tick.tick().await;
        let now = Instant::now();
        if end.is_some_and(|e| now >= e) {
            return Ok(());
        }
        let t = (now - started).as_secs_f64();
        let location = moved(start, velocity_north * t, velocity_east * t);
        streamer
            .send(location)
            .await
            .map_err(|e| format!("sending to the follow stream {target}: {e}"))?;
        if print_messages(client, Some(now + tick.period())).await? {
            return Ok(());
        }
    }
}

/// Publishes one button event on the bus of `$SKYMESH_DOMAIN`.
fn button_bus(button: &str, event: &str, vehicle: u8) -> Result<(Bus, ButtonEvent), String> {
    let b = named(Button::ALL, button, Button::as_str)
        .ok_or_else(|| format!("unknown button `{button}`"))?;
    let e = named(ButtonEventKind::ALL, event, ButtonEventKind::as_str)
        .ok_or_else(|| format!("unknown button event `{event}`"))?;
    let domain = Domain::from_env(None).map_err(|e| e.to_string())?;
    let name = format!("skymesh-solo-{}", std::process::id());
    let bus = Bus::open(&domain, &name, ServiceId::Tool, 0, Stats::new())
        .map_err(|e| format!("cannot join the mesh (domain {}): {e}", domain.name))?;
    Ok((bus, ButtonEvent::new(vehicle, b, e)))
}

async fn run(cli: Cli) -> Result<(), String> {
    if !(cli.wait.is_finite() && cli.wait >= 0.0) {
        return Err(format!("--wait {} must be a number of seconds", cli.wait));
    }
    let message = message_for(&cli.cmd)?;
    let button = match &cli.cmd {
        Cmd::Button {
            button,
            event,
            vehicle,
        } => Some(button_bus(button, event, *vehicle)?),
        _ => None,
    };
    let mut client = AppClient::connect(cli.addr)
        .await
        .map_err(|e| format!("{e} (is solo-gateway running?)"))?;
    if let Some(m) = &message {
        client.send(m).await.map_err(|e| format!("sending: {e}"))?;
    }
    // Held until the end: samples of a publisher that is gone may never be read.
    let mut _publisher = None;
    if let Some((bus, event)) = button {
        let mut publisher = bus
            .publisher::<ButtonEvent>(&topics::input_buttons())
            .map_err(|e| e.to_string())?;
        publisher.publish(event).map_err(|e| e.to_string())?;
        _publisher = Some((bus, publisher));
    }
    let until = match &cli.cmd {
        Cmd::Listen => None,
        Cmd::Follow { .. } => {
            follow(&mut client, &cli).await?;
            Some(Instant::now() + Duration::from_secs_f64(cli.wait))
        }
        _ => Some(Instant::now() + Duration::from_secs_f64(cli.wait)),
    };
    print_messages(&mut client, until).await.map(|_| ())
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("skymesh-solo: {e}");
            ExitCode::FAILURE
        }
    }
}
