//! The gateway's bus side, shared by the services/events loop and the DRC link:
//! the latest vehicle samples in a `watch` channel, and `VehicleCommand`s (source
//! `dji_drc`) published with their `CommandAck` awaited.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/vehicle/{id}/command` | publish | `VehicleCommand` (source `dji_drc`) |
//! | `skymesh/vehicle/{id}/command_ack` | subscribe | `CommandAck` |
//! | `skymesh/vehicle/{id}/state` | subscribe | `VehicleState` |
//! | `skymesh/vehicle/{id}/status` | subscribe | `VehicleStatus` |
//! | `skymesh/vehicle/{id}/payload` | subscribe | `PayloadState` |
//! | `skymesh/vehicle/{id}/authority` | subscribe | `AuthorityState` |
//! | `skymesh/vehicle/{id}/arbiter_events` | subscribe | `ArbiterEvent` |

use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::topics;
use skymesh_ipc_types::{
    ArbiterEvent, AuthorityDomain, AuthorityState, Command, CommandAck, CommandError,
    CommandSource, PayloadState, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, CancellationToken, Publisher};
use tokio::sync::{broadcast, oneshot, watch};

/// Our command source.
pub const SOURCE: CommandSource = CommandSource::DjiDrc;

/// The latest sample of each vehicle topic (`None` until the first arrives).
#[derive(Debug, Clone, Copy, Default)]
pub struct Snapshot {
    pub state: Option<VehicleState>,
    pub status: Option<VehicleStatus>,
    pub payload: Option<PayloadState>,
    pub authority: Option<AuthorityState>,
}

impl Snapshot {
    /// True when the arbiter says we hold flight authority.
    pub fn holds_flight(&self) -> bool {
        self.authority.and_then(|a| a.flight()) == Some(SOURCE)
    }

    /// True when the arbiter says we hold payload authority.
    pub fn holds_payload(&self) -> bool {
        self.authority.and_then(|a| a.payload()) == Some(SOURCE)
    }
}

/// Why a command did not succeed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandFailure {
    /// The command does not pass `Command::validate` (a gateway bug or a value the
    /// proto layer let through): never published.
    #[error("invalid command: {0}")]
    Invalid(#[from] CommandError),
    /// The bus refused the sample.
    #[error("bus: {0}")]
    Bus(String),
    /// No `CommandAck` within the timeout (autopilot-link not running?).
    #[error("no acknowledgement within {0:?}")]
    NoAck(Duration),
    /// Refused by the arbiter or the autopilot (`CommandAck` with its reason).
    #[error("refused: {}", .0.detail)]
    Refused(CommandAck),
}

type Pending = Arc<Mutex<HashMap<u32, oneshot::Sender<CommandAck>>>>;

/// Cheap to clone; every clone talks to the same ports.
#[derive(Debug, Clone)]
pub struct VehicleLink {
    vehicle_id: u8,
    commands: Arc<Mutex<Publisher<VehicleCommand>>>,
    next_id: Arc<AtomicU32>,
    pending: Pending,
    snapshot: watch::Receiver<Snapshot>,
    events: broadcast::Sender<ArbiterEvent>,
    ack_timeout: Duration,
    /// `CLOCK_MONOTONIC` ns of the last flight / payload command published (0 = none).
    last_sent_ns: Arc<[AtomicU64; 2]>,
}

fn domain_slot(domain: AuthorityDomain) -> usize {
    match domain {
        AuthorityDomain::Flight => 0,
        AuthorityDomain::Payload => 1,
    }
}

impl VehicleLink {
    /// Opens the ports and starts the task that follows the subscriptions (it ends
    /// with `shutdown`).
    pub fn open(
        bus: &Bus,
        vehicle_id: u8,
        ack_timeout: Duration,
        shutdown: CancellationToken,
    ) -> anyhow::Result<VehicleLink> {
        let commands = bus
            .publisher(&topics::vehicle_command(vehicle_id))
            .context("opening the vehicle command topic")?;
        let mut acks = bus
            .subscriber::<CommandAck>(&topics::vehicle_command_ack(vehicle_id))
            .context("opening the command ack topic")?;
        let mut state = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(vehicle_id))
            .context("opening the vehicle state topic")?;
        let mut status = bus
            .subscriber::<VehicleStatus>(&topics::vehicle_status(vehicle_id))
            .context("opening the vehicle status topic")?;
        let mut payload = bus
            .subscriber::<PayloadState>(&topics::vehicle_payload(vehicle_id))
            .context("opening the payload topic")?;
        let mut authority = bus
            .subscriber::<AuthorityState>(&topics::vehicle_authority(vehicle_id))
            .context("opening the authority topic")?;
        let mut arbiter = bus
            .subscriber::<ArbiterEvent>(&topics::vehicle_arbiter_events(vehicle_id))
            .context("opening the arbiter events topic")?;
        // Latest-value topics may already hold a sample.
        let snap = Snapshot {
            state: state.latest().ok().flatten(),
            status: status.latest().ok().flatten(),
            payload: payload.latest().ok().flatten(),
            authority: authority.latest().ok().flatten(),
        };
        let (tx, rx) = watch::channel(snap);
        let (events, _) = broadcast::channel(64);
        let pending: Pending = Arc::default();
        let link = VehicleLink {
            vehicle_id,
            commands: Arc::new(Mutex::new(commands)),
            next_id: Arc::new(AtomicU32::new(1)),
            pending: pending.clone(),
            snapshot: rx,
            events: events.clone(),
            ack_timeout,
            last_sent_ns: Arc::new([AtomicU64::new(0), AtomicU64::new(0)]),
        };
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = shutdown.cancelled() => break,
                    r = acks.recv() => match r {
                        Ok(ack) => {
                            if ack.source == SOURCE.to_wire() {
                                let waiter = pending.lock().unwrap_or_else(|p| p.into_inner()).remove(&ack.command_id);
                                if let Some(w) = waiter {
                                    let _ = w.send(ack);
                                }
                            }
                        }
                        Err(e) => { tracing::error!(error = %e, "command ack subscription failed"); break; }
                    },
                    r = state.recv() => match r {
                        Ok(s) => tx.send_modify(|x| x.state = Some(s)),
                        Err(e) => { tracing::error!(error = %e, "vehicle state subscription failed"); break; }
                    },
                    r = status.recv() => match r {
                        Ok(s) => tx.send_modify(|x| x.status = Some(s)),
                        Err(e) => { tracing::error!(error = %e, "vehicle status subscription failed"); break; }
                    },
                    r = payload.recv() => match r {
                        Ok(s) => tx.send_modify(|x| x.payload = Some(s)),
                        Err(e) => { tracing::error!(error = %e, "payload subscription failed"); break; }
                    },
                    r = authority.recv() => match r {
                        Ok(s) => tx.send_modify(|x| x.authority = Some(s)),
                        Err(e) => { tracing::error!(error = %e, "authority subscription failed"); break; }
                    },
                    r = arbiter.recv() => match r {
                        Ok(e) => { let _ = events.send(e); }
                        Err(e) => { tracing::error!(error = %e, "arbiter events subscription failed"); break; }
                    },
                }
            }
        });
        Ok(link)
    }

    pub fn vehicle_id(&self) -> u8 {
        self.vehicle_id
    }

    /// The latest samples (a copy).
    pub fn snapshot(&self) -> Snapshot {
        *self.snapshot.borrow()
    }

    /// Changes of the latest samples.
    pub fn watch(&self) -> watch::Receiver<Snapshot> {
        self.snapshot.clone()
    }

    /// Arbiter events (refusals, pre-emptions, geofence, failsafes) as they arrive.
    pub fn arbiter_events(&self) -> broadcast::Receiver<ArbiterEvent> {
        self.events.subscribe()
    }

    /// Publishes `command` (max age `max_age_ms`, 0 = the arbiter's default) without
    /// waiting for its ack; returns its command id. For stick setpoints at 10 Hz.
    pub fn send(&self, command: &Command, max_age_ms: u32) -> Result<u32, CommandFailure> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        self.publish(id, command, max_age_ms)?;
        Ok(id)
    }

    /// Publishes `command` and waits for its `CommandAck`: `Ok(ack)` when accepted
    /// (or accepted-limited), else the failure.
    pub async fn command(
        &self,
        command: &Command,
        max_age_ms: u32,
    ) -> Result<CommandAck, CommandFailure> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = oneshot::channel();
        self.lock_pending().insert(id, tx);
        if let Err(e) = self.publish(id, command, max_age_ms) {
            self.lock_pending().remove(&id);
            return Err(e);
        }
        match tokio::time::timeout(self.ack_timeout, rx).await {
            Ok(Ok(ack)) if ack.is_accepted() => Ok(ack),
            Ok(Ok(ack)) => Err(CommandFailure::Refused(ack)),
            Ok(Err(_)) | Err(_) => {
                self.lock_pending().remove(&id);
                Err(CommandFailure::NoAck(self.ack_timeout))
            }
        }
    }

    fn publish(&self, id: u32, command: &Command, max_age_ms: u32) -> Result<(), CommandFailure> {
        let mut sample = VehicleCommand::new(self.vehicle_id, SOURCE, id, command)?;
        sample.max_age_ms = max_age_ms;
        self.commands
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .publish(sample)
            .map(|_| ())
            .map_err(|e| CommandFailure::Bus(e.to_string()))?;
        if let Some(domain) = command.kind().authority() {
            self.last_sent_ns[domain_slot(domain)]
                .store(skymesh_runtime::clock::monotonic_ns(), Ordering::Relaxed);
        }
        Ok(())
    }

    /// How long since the last command of `domain` was published (any command of a
    /// domain keeps its authority alive at the arbiter); `None` if never.
    pub fn idle_for(&self, domain: AuthorityDomain) -> Option<Duration> {
        let at = self.last_sent_ns[domain_slot(domain)].load(Ordering::Relaxed);
        (at != 0).then(|| {
            Duration::from_nanos(skymesh_runtime::clock::monotonic_ns().saturating_sub(at))
        })
    }

    fn lock_pending(&self) -> std::sync::MutexGuard<'_, HashMap<u32, oneshot::Sender<CommandAck>>> {
        self.pending.lock().unwrap_or_else(|p| p.into_inner())
    }
}
