//! The gateway's one loop: the UDP socket, the bus subscriptions and the engine's
//! next deadline feed the [`Engine`]; what it returns is sent, published, counted and
//! logged here.

use std::collections::HashSet;
use std::net::SocketAddr;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context as _;
use imc_proto::{encode_datagram, Header};
use skymesh_runtime::Context;
use tokio::net::UdpSocket;

use crate::config::Settings;
use crate::describe::{describe, message_name};
use crate::drops::Drops;
use crate::engine::{Engine, Outputs, Send};
use crate::ipc::Ports;
use crate::metrics::{Direction, Metrics};

/// The longest sleep with nothing scheduled (idle, no peers): a wake-up whose tick
/// finds nothing to do; only bounds the wait, no deadline depends on it.
const IDLE_WAIT: Duration = Duration::from_secs(60);
/// Receive buffer: larger than any UDP payload.
const RECV_BUFFER: usize = 65_536;
/// Destinations remembered as failing (each logged once).
const MAX_FAILING: usize = 1024;

/// Seconds since the Unix epoch (IMC header timestamps).
fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Writes IMC datagrams: little-endian, our address and entity as source.
#[derive(Debug)]
struct Sender {
    address: u16,
    entity: u8,
    metrics: Metrics,
    /// Destinations whose last send failed (logged once until they work again).
    failing: HashSet<SocketAddr>,
}

impl Sender {
    async fn send(&mut self, socket: &UdpSocket, s: &Send) {
        let name = message_name(&s.message);
        let header = Header {
            mgid: 0,
            size: 0,
            timestamp: unix_now(),
            src: self.address,
            src_ent: self.entity,
            dst: s.to.dst,
            dst_ent: s.to.dst_ent,
        };
        let bytes = match encode_datagram(&header, &s.message) {
            Ok(b) => b,
            Err(e) => {
                self.metrics.send_error(name);
                tracing::error!(message = name, error = %e, "cannot encode an IMC message");
                return;
            }
        };
        match socket.send_to(&bytes, s.to.addr).await {
            Ok(_) => {
                self.metrics.message(Direction::Out, name);
                if self.failing.remove(&s.to.addr) {
                    tracing::info!(to = %s.to.addr, "IMC destination reachable again");
                }
                tracing::trace!(to = %s.to.addr, message = %describe(&s.message), "sent");
            }
            Err(e) => {
                self.metrics.send_error(name);
                if self.failing.len() >= MAX_FAILING {
                    self.failing.clear();
                }
                if self.failing.insert(s.to.addr) {
                    tracing::warn!(
                        to = %s.to.addr,
                        message = name,
                        error = %e,
                        "cannot send to this IMC destination (logged once until it works again)"
                    );
                } else {
                    tracing::debug!(to = %s.to.addr, message = name, error = %e, "send failed");
                }
            }
        }
    }
}

/// Carries out one round of outputs. A bus failure is fatal (the service is
/// restarted); a socket failure is not.
async fn execute(
    out: Outputs,
    socket: &UdpSocket,
    ports: &mut Ports,
    sender: &mut Sender,
    drops: &mut Drops,
    metrics: &Metrics,
    now: Instant,
) -> anyhow::Result<()> {
    for name in out.received {
        metrics.message(Direction::In, name);
    }
    for d in &out.drops {
        drops.record(d, now);
    }
    for request in out.hardware {
        tracing::debug!(id = request.request_id, op = request.op, name = %request.name, "hardware request");
        ports
            .hardware_requests
            .publish(request)
            .context("publishing a hardware request")?;
        metrics.published("hardware_request");
    }
    for command in out.commands {
        tracing::debug!(
            id = command.command_id,
            kind = command.kind,
            "vehicle command"
        );
        ports
            .commands
            .publish(command)
            .context("publishing a vehicle command")?;
        metrics.published("command");
    }
    for button in out.buttons {
        tracing::debug!(button = button.button, event = button.event, "button event");
        ports
            .buttons
            .publish(button)
            .context("publishing a button event")?;
        metrics.published("button");
    }
    for s in &out.sends {
        sender.send(socket, s).await;
    }
    Ok(())
}

/// Hands the engine the newest hardware state, if one is pending: before a query is
/// answered and before a hardware reply is handled, so a query right after a change
/// is answered from the state that contains it (the hardware service publishes its
/// state before its replies).
fn refresh_hardware(ports: &Ports, engine: &mut Engine) -> anyhow::Result<()> {
    if let Some(s) = ports
        .hardware_state
        .latest()
        .context("receiving the hardware state")?
    {
        engine.on_hardware_state(s);
    }
    Ok(())
}

/// Hands the engine the newest vehicle state and status. They are read only when a
/// datagram or a tick may use them (teleoperation, remote actions, Announce), so the
/// loop does not wake for every VehicleState (50 Hz) while idle.
fn refresh_vehicle(ports: &Ports, engine: &mut Engine) -> anyhow::Result<()> {
    if let Some(s) = ports
        .vehicle_state
        .latest()
        .context("receiving the vehicle state")?
    {
        engine.on_vehicle_state(s);
    }
    if let Some(s) = ports
        .vehicle_status
        .latest()
        .context("receiving the vehicle status")?
    {
        engine.on_vehicle_status(s);
    }
    Ok(())
}

/// The allow-list settings that are valid but probably not what was meant.
fn warn_about_allowed_peers(settings: &Settings, local: SocketAddr) {
    let allowed = &settings.allowed_peers;
    if allowed.entries().is_empty() {
        tracing::warn!("allowed_peers is empty: every IMC datagram is dropped (not_allowed)");
        return;
    }
    // An entry's network address is loopback only for a network inside the loopback
    // (0.0.0.0/0 starts at 0.0.0.0).
    let only_loopback = allowed.entries().iter().all(|n| {
        let text = n.to_string();
        let addr = text.split('/').next().unwrap_or_default();
        addr.parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.to_canonical().is_loopback())
    });
    if !local.ip().is_loopback() && only_loopback {
        tracing::warn!(
            listen = %local,
            %allowed,
            "imc-gateway listens beyond the loopback but allowed_peers admits only loopback peers: \
             remote peers are dropped (not_allowed); add their addresses or networks to allowed_peers"
        );
    }
    for p in &settings.static_peers {
        if !allowed.contains(p.ip()) {
            tracing::warn!(
                peer = %p,
                %allowed,
                "static peer is not in allowed_peers: it gets heartbeats but its messages are dropped"
            );
        }
    }
}

/// Runs the gateway on an already-bound socket until `ctx.shutdown` is cancelled
/// (then `Ok`) or the bus fails (then `Err`). Marks the service ready once the
/// hardware service's state is in (or `hardware_timeout` passed without it).
pub async fn run(settings: Settings, socket: UdpSocket, ctx: Context) -> anyhow::Result<()> {
    let local = socket.local_addr().context("reading the bound address")?;
    let mut ports = Ports::open(&ctx.bus, settings.vehicle_id)?;
    let metrics = Metrics::new(&ctx.stats);
    let mut drops = Drops::new(metrics.clone());
    let mut sender = Sender {
        address: settings.address,
        entity: settings.entity,
        metrics: metrics.clone(),
        failing: HashSet::new(),
    };
    tracing::info!(
        listen = %local,
        address = format!("{:#06x}", settings.address),
        entity = settings.entity,
        system_name = %settings.system_name,
        vehicle_id = settings.vehicle_id,
        allowed_peers = %settings.allowed_peers,
        static_peers = ?settings.static_peers,
        announce_to = ?settings.announce_destinations,
        buttons = %crate::engine::button_ids(&settings.buttons),
        "imc-gateway serving IMC over UDP"
    );
    warn_about_allowed_peers(&settings, local);
    let hardware_wait = settings.hardware_timeout;
    let mut engine = Engine::new(settings, local, ports.origin, Instant::now());
    metrics.peers.set(engine.peer_count() as f64);
    // Ready means able to serve: power channel, LED and GPIO queries are answered from
    // the hardware service's state, which a new subscriber receives only with the
    // service's next publication (up to its 1 s period later). Wait for it, at most
    // `hardware_timeout`; without it the gateway serves anyway (those queries are
    // dropped as no_hardware_state, logged) rather than stay down with the hardware.
    let started = Instant::now();
    tokio::select! {
        _ = ctx.shutdown.cancelled() => {
            tracing::info!("imc-gateway stopped before it was ready");
            return Ok(());
        }
        r = tokio::time::timeout(hardware_wait, ports.hardware_state.recv()) => match r {
            Ok(state) => {
                engine.on_hardware_state(state.context("receiving the hardware state")?);
                tracing::debug!(waited_ms = started.elapsed().as_millis() as u64, "hardware state received");
            }
            Err(_) => tracing::info!(
                waited_ms = hardware_wait.as_millis() as u64,
                "no hardware state yet: serving without it (hardware queries are dropped until it comes)"
            ),
        },
    }
    ctx.ready();

    let mut buf = vec![0u8; RECV_BUFFER];
    loop {
        let mut out = Outputs::default();
        // Wake for the engine's next real deadline (peer expiry, Heartbeat, Announce,
        // reply timeouts, power-down progress), not on a fixed tick: idle with no
        // peers that is never.
        let now = Instant::now();
        let wake = engine.next_due(now).unwrap_or(now + IDLE_WAIT);
        tokio::select! {
            _ = ctx.shutdown.cancelled() => break,
            r = socket.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    refresh_vehicle(&ports, &mut engine)?;
                    refresh_hardware(&ports, &mut engine)?;
                    engine.on_datagram(from, &buf[..n], Instant::now(), &mut out);
                }
                // Unconnected UDP sockets report little; nothing here is the peer's fault
                // or fatal. A short pause keeps a persistent error from spinning.
                Err(e) => {
                    tracing::debug!(error = %e, "UDP receive failed");
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            },
            r = ports.hardware_replies.recv() => {
                let reply = r.context("receiving hardware replies")?;
                refresh_hardware(&ports, &mut engine)?;
                engine.on_hardware_reply(&reply, Instant::now(), &mut out);
            }
            r = ports.hardware_state.recv() => {
                engine.on_hardware_state(r.context("receiving the hardware state")?);
            }
            r = ports.acks.recv() => {
                engine.on_command_ack(&r.context("receiving command acks")?, &mut out);
            }
            _ = tokio::time::sleep_until(wake.into()) => {
                refresh_vehicle(&ports, &mut engine)?;
                engine.tick(Instant::now(), &mut out);
            }
        }
        execute(
            out,
            &socket,
            &mut ports,
            &mut sender,
            &mut drops,
            &metrics,
            Instant::now(),
        )
        .await?;
        metrics.peers.set(engine.peer_count() as f64);
    }
    tracing::info!("imc-gateway stopped");
    Ok(())
}
