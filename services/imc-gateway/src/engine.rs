//! The gateway's decisions (pure, explicit time): datagrams and bus samples in,
//! [`Outputs`] out. The glue (`gateway.rs`) owns the socket and the bus ports,
//! feeds this engine and carries out what it returns; so every rule of the gateway
//! is tested here without sockets or shared memory.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use imc_proto::{decode_datagram, Announce, Message, PowerOp, RemoteActionsOp, SystemType};
use skymesh_ipc_types::{
    Button, ButtonEvent, ButtonEventKind, Command, CommandAck, CommandSource, FlightMode,
    HardwareReply, HardwareRequest, HardwareState, SampleHeader, VehicleCommand, VehicleState,
    VehicleStatus,
};

use crate::commands::{AckOutcome, Commands};
use crate::config::Settings;
use crate::describe::message_name;
use crate::hardware::{self, Outcome, PowerWatch, Requests, WatchStep};
use crate::peers::{Destination, Every, Peers};
use crate::teleop::{Teleop, VehicleView};

/// How long autopilot-link may take to ack a command before it is forgotten
/// (`command_timeout`); it always answers well within this (command timeout ×
/// retries), so this only bounds memory when it is not running.
pub const COMMAND_ACK_TIMEOUT: Duration = Duration::from_secs(15);
/// Period of the power-down progress reports.
pub const PROGRESS_EVERY: Duration = Duration::from_secs(1);

/// An IMC message for a peer.
#[derive(Debug, Clone, PartialEq)]
pub struct Send {
    pub to: Destination,
    pub message: Message,
}

/// Input that was refused or not acted on (`skymesh_imc_dropped_total{reason}`).
#[derive(Debug, Clone, PartialEq)]
pub struct Dropped {
    pub reason: &'static str,
    pub peer: Option<SocketAddr>,
    pub detail: String,
    /// Logged at debug only (not a fault of the peer, e.g. a REPORT it sent us).
    pub quiet: bool,
}

impl Dropped {
    fn new(reason: &'static str, peer: SocketAddr, detail: impl Into<String>) -> Self {
        Dropped {
            reason,
            peer: Some(peer),
            detail: detail.into(),
            quiet: false,
        }
    }

    fn quiet(mut self) -> Self {
        self.quiet = true;
        self
    }
}

/// What to do after one input.
#[derive(Debug, Default, PartialEq)]
pub struct Outputs {
    /// Messages accepted from peers (`skymesh_imc_messages_total{direction="in"}`).
    pub received: Vec<&'static str>,
    pub sends: Vec<Send>,
    pub hardware: Vec<HardwareRequest>,
    pub commands: Vec<VehicleCommand>,
    pub buttons: Vec<ButtonEvent>,
    pub drops: Vec<Dropped>,
}

/// Everything the gateway knows and decides.
#[derive(Debug)]
pub struct Engine {
    settings: Settings,
    /// The bound socket address (its port is in our Announce).
    local: SocketAddr,
    peers: Peers,
    teleop: Teleop,
    hardware: Requests,
    commands: Commands,
    vehicle: VehicleView,
    hardware_state: Option<HardwareState>,
    power_watch: Option<PowerWatch>,
    heartbeat: Every,
    announce: Every,
    progress: Every,
}

impl Engine {
    /// `origin`: the header fields our bus publishers stamp (hardware replies for us
    /// carry them).
    pub fn new(settings: Settings, local: SocketAddr, origin: SampleHeader, now: Instant) -> Self {
        Engine {
            peers: Peers::new(&settings.static_peers, settings.peer_timeout),
            teleop: Teleop::new(settings.teleop.clone()),
            hardware: Requests::new(origin, settings.hardware_timeout),
            commands: Commands::new(COMMAND_ACK_TIMEOUT),
            vehicle: VehicleView::default(),
            hardware_state: None,
            power_watch: None,
            heartbeat: Every::starting(settings.heartbeat_interval, now),
            announce: Every::starting(settings.announce_interval, now),
            progress: Every::starting(PROGRESS_EVERY, now),
            local,
            settings,
        }
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Peers that get heartbeats now.
    pub fn peer_count(&self) -> usize {
        self.peers.len()
    }

    pub fn peers(&self) -> &Peers {
        &self.peers
    }

    /// One datagram from `from`. A peer outside `allowed_peers` is dropped
    /// (`not_allowed`) before anything is decoded: it commands nothing and does not
    /// become a known peer (no heartbeats, no replies).
    pub fn on_datagram(&mut self, from: SocketAddr, bytes: &[u8], now: Instant, out: &mut Outputs) {
        if !self.settings.allowed_peers.contains(from.ip()) {
            out.drops.push(Dropped::new(
                "not_allowed",
                from,
                format!(
                    "{} bytes from {}, which is not in allowed_peers {}",
                    bytes.len(),
                    from.ip(),
                    self.settings.allowed_peers
                ),
            ));
            return;
        }
        let packet = match decode_datagram(bytes) {
            Ok(p) => p,
            Err(e) => {
                out.drops.push(Dropped::new(e.kind(), from, e.to_string()));
                return;
            }
        };
        let h = packet.header;
        if h.dst != self.settings.address && h.dst != imc_proto::ADDR_NONE {
            out.drops.push(Dropped::new(
                "not_for_us",
                from,
                format!(
                    "{} for system {:#06x}; we are {:#06x}",
                    message_name(&packet.message),
                    h.dst,
                    self.settings.address
                ),
            ));
            return;
        }
        if let Some(evicted) = self.peers.seen(from, h.src, h.src_ent, now) {
            self.release_buttons_of(evicted, out);
        }
        let reply_to = Destination {
            addr: from,
            dst: h.src,
            dst_ent: h.src_ent,
        };
        let name = message_name(&packet.message);
        match self.handle(packet.message, reply_to, now, out) {
            Ok(()) => out.received.push(name),
            Err(d) => out.drops.push(d),
        }
    }

    fn handle(
        &mut self,
        message: Message,
        reply_to: Destination,
        now: Instant,
        out: &mut Outputs,
    ) -> Result<(), Dropped> {
        let from = reply_to.addr;
        let name = message_name(&message);
        if let Some(request) = hardware::request_for(&message) {
            let (request, answer) =
                request.map_err(|e| Dropped::new(e.reason(), from, format!("{name}: {e}")))?;
            let request = self
                .hardware
                .start(request, answer, reply_to, name, now)
                .ok_or_else(|| {
                    Dropped::new(
                        "hardware_busy",
                        from,
                        format!(
                            "{name}: {} requests already wait for the hardware service",
                            hardware::MAX_PENDING
                        ),
                    )
                })?;
            out.hardware.push(request);
            return Ok(());
        }
        let actuators = &self.settings.actuators;
        let refused = |e: crate::actuators::Refusal| Dropped::new(e.reason(), from, e.to_string());
        match message {
            Message::Heartbeat => Ok(()),
            Message::Announce(a) => {
                self.peers.announced(from, &a.sys_name);
                Ok(())
            }
            Message::CameraZoom { id, zoom, action } => {
                let cmd = crate::actuators::zoom(id, zoom, action);
                self.command(cmd, name, from, None, now, out)
            }
            Message::SetThrusterActuation { id, value } => {
                let cmd = actuators.thruster(id, value).map_err(refused)?;
                self.command(cmd, name, from, None, now, out)
            }
            Message::SetServoPosition { id, value } => {
                let cmd = actuators.servo(id, value).map_err(refused)?;
                self.command(cmd, name, from, None, now, out)
            }
            Message::SetControlSurfaceDeflection { id, angle } => {
                let cmd = actuators.surface(id, angle).map_err(refused)?;
                self.command(cmd, name, from, None, now, out)
            }
            Message::SetPwm {
                id,
                period,
                duty_cycle,
            } => {
                let (cmd, map) = actuators.pwm(id, period, duty_cycle).map_err(refused)?;
                let reply = Message::Pwm {
                    id,
                    period: map.period_us,
                    duty_cycle,
                };
                self.command(cmd, name, from, Some((reply_to, reply)), now, out)
            }
            Message::RemoteActionsRequest { op, .. } => match op {
                RemoteActionsOp::Query => {
                    out.sends.push(Send {
                        to: reply_to,
                        message: Message::RemoteActionsRequest {
                            op: RemoteActionsOp::Report,
                            actions: self.teleop.settings().actions_text(),
                        },
                    });
                    Ok(())
                }
                RemoteActionsOp::Report | RemoteActionsOp::Register => Err(Dropped::new(
                    "unsupported",
                    from,
                    format!(
                        "RemoteActionsRequest {op:?}: skymesh serves its own action table, it does not take a peer's"
                    ),
                )
                .quiet()),
            },
            Message::RemoteActions { actions } => self.remote_actions(from, &actions, now, out),
            Message::ButtonEvent { button, value } => {
                let Some(b) = self.settings.buttons.get(&button).copied() else {
                    return Err(Dropped::new(
                        "unmapped",
                        from,
                        format!("ButtonEvent button {button} is not in [buttons]"),
                    ));
                };
                let kind = match value {
                    1 => ButtonEventKind::Press,
                    0 => ButtonEventKind::Release,
                    other => {
                        return Err(Dropped::new(
                            "invalid_value",
                            from,
                            format!("ButtonEvent value {other}: 1 is a press, 0 a release"),
                        ))
                    }
                };
                out.buttons
                    .push(ButtonEvent::new(self.settings.vehicle_id, b, kind));
                Ok(())
            }
            Message::QueryPowerChannelState => {
                let state = self.hardware_state.as_ref().ok_or_else(|| {
                    Dropped::new(
                        "no_hardware_state",
                        from,
                        "QueryPowerChannelState: no HardwareState from the hardware service yet",
                    )
                })?;
                if state.channels().is_empty() {
                    // IMC has no empty answer: without this the query would vanish
                    // uncounted.
                    return Err(Dropped::new(
                        "no_power_channels",
                        from,
                        "QueryPowerChannelState: the hardware service has no power channels",
                    ));
                }
                for ch in state.channels() {
                    out.sends.push(Send {
                        to: reply_to,
                        message: Message::PowerChannelState {
                            name: ch.name.as_str().to_string(),
                            state: if ch.on != 0 {
                                imc_proto::ChannelState::On
                            } else {
                                imc_proto::ChannelState::Off
                            },
                        },
                    });
                }
                Ok(())
            }
            Message::PowerChannelState { .. }
            | Message::LedBrightness { .. }
            | Message::Pwm { .. }
            | Message::GpioState { .. } => Err(Dropped::new(
                "unsupported",
                from,
                format!("{name} is a report a system sends about itself; skymesh does not take it from a peer"),
            )),
            // Hardware messages were handled above.
            Message::LcdControl { .. }
            | Message::PowerOperation { .. }
            | Message::PowerChannelControl { .. }
            | Message::QueryLedBrightness { .. }
            | Message::SetLedBrightness { .. }
            | Message::GpioStateGet { .. }
            | Message::GpioStateSet { .. } => Ok(()),
        }
    }

    /// Publishes `cmd` as source `imc` and remembers it until its ack.
    fn command(
        &mut self,
        cmd: Command,
        name: &'static str,
        from: SocketAddr,
        on_accept: Option<(Destination, Message)>,
        now: Instant,
        out: &mut Outputs,
    ) -> Result<(), Dropped> {
        let mut sample = VehicleCommand::new(self.settings.vehicle_id, CommandSource::Imc, 0, &cmd)
            .map_err(|e| Dropped::new("invalid_value", from, format!("{name}: {e}")))?;
        if cmd.kind().is_setpoint() {
            sample.max_age_ms = self.settings.teleop.max_age_ms;
        }
        sample.command_id = self
            .commands
            .start(from, name, on_accept, now)
            .ok_or_else(|| {
                Dropped::new(
                    "command_busy",
                    from,
                    format!("{name}: too many commands wait for their ack"),
                )
            })?;
        out.commands.push(sample);
        Ok(())
    }

    fn remote_actions(
        &mut self,
        from: SocketAddr,
        text: &str,
        now: Instant,
        out: &mut Outputs,
    ) -> Result<(), Dropped> {
        let t = self
            .teleop
            .on_remote_actions(from, text, &self.vehicle, now)
            .map_err(|e| Dropped::new(e.reason(), from, format!("RemoteActions: {e}")))?;
        for unknown in t.new_unknown {
            out.drops.push(Dropped::new(
                "unknown_action",
                from,
                format!("RemoteActions: action {unknown:?} is not in [teleop] actions; ignored"),
            ));
        }
        if t.set_guided {
            tracing::info!(peer = %from, "teleoperation: asking for GUIDED (switch_to_guided)");
            self.command(
                Command::SetMode(FlightMode::Guided),
                "RemoteActions",
                from,
                None,
                now,
                out,
            )?;
        }
        if let Some(v) = t.velocity {
            self.command(v, "RemoteActions", from, None, now, out)?;
        }
        for (button, kind) in t.buttons {
            out.buttons
                .push(ButtonEvent::new(self.settings.vehicle_id, button, kind));
        }
        Ok(())
    }

    fn release_buttons_of(&mut self, peer: SocketAddr, out: &mut Outputs) {
        for b in self.teleop.forget(peer) {
            out.buttons.push(ButtonEvent::new(
                self.settings.vehicle_id,
                b,
                ButtonEventKind::Release,
            ));
        }
    }

    /// A reply of the hardware service (anyone's: ours are picked by header and id).
    pub fn on_hardware_reply(&mut self, reply: &HardwareReply, now: Instant, out: &mut Outputs) {
        let Some(p) = self.hardware.answered(reply) else {
            return;
        };
        match hardware::outcome(&p, reply) {
            Outcome::Reply(message) => {
                if matches!(
                    message,
                    Message::PowerOperation {
                        op: PowerOp::PowerDownInProgress,
                        ..
                    }
                ) {
                    self.power_watch = Some(PowerWatch::new(p.reply_to, now));
                }
                out.sends.push(Send {
                    to: p.reply_to,
                    message,
                });
            }
            Outcome::Done => {}
            Outcome::Failed {
                reason,
                detail,
                reply,
            } => {
                out.drops.push(Dropped::new(
                    reason,
                    p.reply_to.addr,
                    format!("{} {:?}: {detail}", p.message, p.name),
                ));
                if let Some(message) = reply {
                    out.sends.push(Send {
                        to: p.reply_to,
                        message,
                    });
                }
            }
        }
    }

    pub fn on_hardware_state(&mut self, state: HardwareState) {
        self.hardware_state = Some(state);
    }

    pub fn on_command_ack(&mut self, ack: &CommandAck, out: &mut Outputs) {
        let Some((p, outcome)) = self.commands.on_ack(ack) else {
            return;
        };
        match outcome {
            AckOutcome::Accepted => {
                if let Some((to, message)) = p.on_accept {
                    out.sends.push(Send { to, message });
                }
            }
            AckOutcome::Refused { reason, detail } => out.drops.push(Dropped::new(
                reason,
                p.peer,
                format!("{}: refused by autopilot-link: {detail}", p.message),
            )),
        }
    }

    pub fn on_vehicle_state(&mut self, state: VehicleState) {
        self.vehicle.state = Some(state);
    }

    pub fn on_vehicle_status(&mut self, status: VehicleStatus) {
        self.vehicle.status = Some(status);
    }

    /// What is due at `now`: peer expiry, Heartbeat, Announce, timeouts, power-down
    /// progress. Call it at [`Engine::next_due`] (or more often); it does each thing at
    /// its own period.
    pub fn tick(&mut self, now: Instant, out: &mut Outputs) {
        for gone in self.peers.expire(now) {
            tracing::info!(peer = %gone, "IMC peer silent; no more heartbeats");
            self.release_buttons_of(gone, out);
        }
        if self.heartbeat.due(now) {
            for to in self.peers.heartbeat_targets() {
                out.sends.push(Send {
                    to,
                    message: Message::Heartbeat,
                });
            }
        }
        if !self.settings.announce_destinations.is_empty() && self.announce.due(now) {
            let announce = self.announce_message();
            for addr in &self.settings.announce_destinations {
                out.sends.push(Send {
                    to: Destination::anonymous(*addr),
                    message: Message::Announce(announce.clone()),
                });
            }
        }
        for p in self.hardware.expire(now) {
            out.drops.push(Dropped::new(
                "hardware_timeout",
                p.reply_to.addr,
                format!(
                    "{} {:?}: no reply from the hardware service within {:?}",
                    p.message, p.name, self.settings.hardware_timeout
                ),
            ));
        }
        for p in self.commands.expire(now) {
            out.drops.push(Dropped::new(
                "command_timeout",
                p.peer,
                format!(
                    "{}: no CommandAck within {COMMAND_ACK_TIMEOUT:?} (is autopilot-link running?)",
                    p.message
                ),
            ));
        }
        if self.progress.due(now) {
            if let Some(watch) = self.power_watch.as_mut() {
                let to = watch.requester;
                match watch.step(self.hardware_state.as_ref(), now) {
                    WatchStep::Progress(left) => out.sends.push(Send {
                        to,
                        message: Message::PowerOperation {
                            op: PowerOp::PowerDownInProgress,
                            time_remain: left,
                            sched_time: 0.0,
                        },
                    }),
                    WatchStep::Aborted => {
                        self.power_watch = None;
                        out.sends.push(Send {
                            to,
                            message: Message::PowerOperation {
                                op: PowerOp::PowerDownAborted,
                                time_remain: 0.0,
                                sched_time: 0.0,
                            },
                        });
                    }
                    WatchStep::Wait => {}
                }
            }
        }
    }

    /// When [`Engine::tick`] next has something to do: a dynamic peer's expiry, the
    /// next Heartbeat (only while someone gets one), the next Announce (only with
    /// destinations), a hardware or command reply deadline, the power-down progress
    /// (only while watching one). `None`: nothing scheduled (idle, no peers), so the
    /// loop need not wake until a datagram or a bus sample changes that.
    pub fn next_due(&self, now: Instant) -> Option<Instant> {
        let heartbeat = (!self.peers.is_empty()).then(|| self.heartbeat.next_due(now));
        let announce =
            (!self.settings.announce_destinations.is_empty()).then(|| self.announce.next_due(now));
        let progress = self
            .power_watch
            .as_ref()
            .map(|_| self.progress.next_due(now));
        [
            self.peers.next_expiry(),
            heartbeat,
            announce,
            self.hardware.next_deadline(),
            self.commands.next_deadline(),
            progress,
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Our Announce: name, type UAV, position from the vehicle (zeros until known),
    /// and the services string with our address and port.
    pub fn announce_message(&self) -> Announce {
        let (lat, lon, height) = match self.vehicle.state {
            Some(s) if s.position_valid != 0 => {
                (s.lat_deg.to_radians(), s.lon_deg.to_radians(), s.alt_msl_m)
            }
            _ => (0.0, 0.0, 0.0),
        };
        let service = SocketAddr::new(self.settings.advertise_address, self.local.port());
        Announce {
            sys_name: self.settings.system_name.clone(),
            sys_type: SystemType::Uav,
            owner: imc_proto::ADDR_NONE,
            lat,
            lon,
            height,
            services: format!("imc+udp://{service}/"),
        }
    }
}

/// The IMC button ids of a mapping (for logs).
pub fn button_ids(map: &BTreeMap<u8, Button>) -> String {
    map.iter()
        .map(|(id, b)| format!("{id}={b}"))
        .collect::<Vec<_>>()
        .join(",")
}

#[cfg(test)]
#[path = "engine_tests.rs"]
mod tests;
