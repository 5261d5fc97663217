//! The gateway's bus side, shared by the services/events loop and the DRC link:
//! the latest vehicle samples in a `watch` channel, and `VehicleCommand`s (source
//! `dji_drc`) published with their `CommandAck` awaited.
//!
//! The latest-value topics (state at the autopilot's `attitude_hz`, status, payload,
//! authority) are not awaited sample by sample while nobody waits for their changes:
//! [`VehicleLink::snapshot`] reads the newest samples when asked, so an idle gateway
//! is not woken 50+ times a second. While a [`VehicleLink::watch`] receiver exists
//! (a DRC session, a panorama settling, a wait for authority) the bus task awaits
//! every sample and the watch sees each change as it arrives.
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
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::topics;
use skymesh_ipc_types::{
    ArbiterEvent, AuthorityDomain, AuthorityState, Command, CommandAck, CommandError,
    CommandSource, PayloadState, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, CancellationToken, IpcError, Publisher, Subscriber};
use tokio::sync::{broadcast, oneshot, watch, Notify};

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

/// The subscriptions behind the [`Snapshot`].
#[derive(Debug)]
struct LatestPorts {
    state: Subscriber<VehicleState>,
    status: Subscriber<VehicleStatus>,
    payload: Subscriber<PayloadState>,
    authority: Subscriber<AuthorityState>,
}

impl LatestPorts {
    /// Takes what is pending (without waiting) into the watch; notifies its
    /// receivers only if something came.
    fn refresh(&self, tx: &watch::Sender<Snapshot>) -> Result<(), IpcError> {
        let state = self.state.latest()?;
        let status = self.status.latest()?;
        let payload = self.payload.latest()?;
        let authority = self.authority.latest()?;
        if state.is_some() || status.is_some() || payload.is_some() || authority.is_some() {
            tx.send_modify(|x| {
                x.state = state.or(x.state);
                x.status = status.or(x.status);
                x.payload = payload.or(x.payload);
                x.authority = authority.or(x.authority);
            });
        }
        Ok(())
    }

    /// Waits for the next sample of any of them and puts it into the watch.
    /// Cancel-safe (every branch is).
    async fn next(&mut self, tx: &watch::Sender<Snapshot>) -> Result<(), (&'static str, IpcError)> {
        tokio::select! {
            r = self.state.recv() => {
                let v = r.map_err(|e| ("vehicle state", e))?;
                tx.send_modify(|x| x.state = Some(v));
            }
            r = self.status.recv() => {
                let v = r.map_err(|e| ("vehicle status", e))?;
                tx.send_modify(|x| x.status = Some(v));
            }
            r = self.payload.recv() => {
                let v = r.map_err(|e| ("payload", e))?;
                tx.send_modify(|x| x.payload = Some(v));
            }
            r = self.authority.recv() => {
                let v = r.map_err(|e| ("authority", e))?;
                tx.send_modify(|x| x.authority = Some(v));
            }
        }
        Ok(())
    }
}

/// What the bus task and every clone share about the latest-value topics.
#[derive(Debug)]
struct Latest {
    tx: watch::Sender<Snapshot>,
    /// The subscriptions while nobody watches (the bus task holds them otherwise).
    ports: Mutex<Option<LatestPorts>>,
    /// Live [`Watch`]es: while above zero the bus task awaits every sample.
    watchers: AtomicUsize,
    /// Wakes the bus task when `watchers` goes from or to zero.
    watchers_changed: Notify,
}

/// A [`watch::Receiver`] of the [`Snapshot`] that keeps the bus task following
/// every sample while it lives (derefs to the receiver).
#[derive(Debug)]
pub struct Watch {
    rx: watch::Receiver<Snapshot>,
    latest: Arc<Latest>,
}

impl std::ops::Deref for Watch {
    type Target = watch::Receiver<Snapshot>;
    fn deref(&self) -> &Self::Target {
        &self.rx
    }
}

impl std::ops::DerefMut for Watch {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.rx
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        if self.latest.watchers.fetch_sub(1, Ordering::AcqRel) == 1 {
            self.latest.watchers_changed.notify_one();
        }
    }
}

/// Cheap to clone; every clone talks to the same ports.
#[derive(Debug, Clone)]
pub struct VehicleLink {
    vehicle_id: u8,
    commands: Arc<Mutex<Publisher<VehicleCommand>>>,
    next_id: Arc<AtomicU32>,
    pending: Pending,
    snapshot: watch::Receiver<Snapshot>,
    latest: Arc<Latest>,
    events: broadcast::Sender<ArbiterEvent>,
    ack_timeout: Duration,
    /// How long an emergency stop may wait for its ack: autopilot-link answers it
    /// only once the autopilot confirmed the stop (BRAKE or the measured speed), up
    /// to its `stop_confirm_timeout_s`.
    stop_ack_timeout: Duration,
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
        timeouts: &crate::config::CommandSettings,
        shutdown: CancellationToken,
    ) -> anyhow::Result<VehicleLink> {
        let commands = bus
            .publisher(&topics::vehicle_command(vehicle_id))
            .context("opening the vehicle command topic")?;
        let mut acks = bus
            .subscriber::<CommandAck>(&topics::vehicle_command_ack(vehicle_id))
            .context("opening the command ack topic")?;
        let state = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(vehicle_id))
            .context("opening the vehicle state topic")?;
        let status = bus
            .subscriber::<VehicleStatus>(&topics::vehicle_status(vehicle_id))
            .context("opening the vehicle status topic")?;
        let payload = bus
            .subscriber::<PayloadState>(&topics::vehicle_payload(vehicle_id))
            .context("opening the payload topic")?;
        let authority = bus
            .subscriber::<AuthorityState>(&topics::vehicle_authority(vehicle_id))
            .context("opening the authority topic")?;
        let mut arbiter = bus
            .subscriber::<ArbiterEvent>(&topics::vehicle_arbiter_events(vehicle_id))
            .context("opening the arbiter events topic")?;
        let (tx, rx) = watch::channel(Snapshot::default());
        // Read newest-first on demand while nobody watches: overwritten samples are
        // by design, not lost.
        let (mut state, mut status, mut payload) = (state, status, payload);
        state.set_newest_only();
        status.set_newest_only();
        payload.set_newest_only();
        let ports = LatestPorts {
            state,
            status,
            payload,
            authority,
        };
        // Latest-value topics may already hold a sample.
        ports
            .refresh(&tx)
            .context("reading the latest vehicle samples")?;
        let latest = Arc::new(Latest {
            tx,
            ports: Mutex::new(Some(ports)),
            watchers: AtomicUsize::new(0),
            watchers_changed: Notify::new(),
        });
        let (events, _) = broadcast::channel(64);
        let pending: Pending = Arc::default();
        let link = VehicleLink {
            vehicle_id,
            commands: Arc::new(Mutex::new(commands)),
            next_id: Arc::new(AtomicU32::new(1)),
            pending: pending.clone(),
            snapshot: rx,
            latest: latest.clone(),
            events: events.clone(),
            ack_timeout: timeouts.ack_timeout,
            stop_ack_timeout: timeouts.stop_ack_timeout,
            last_sent_ns: Arc::new([AtomicU64::new(0), AtomicU64::new(0)]),
        };
        tokio::spawn(async move {
            // The latest-value subscriptions while someone watches; back in
            // `latest.ports` (read on demand by `snapshot`) otherwise.
            let mut following: Option<LatestPorts> = None;
            loop {
                let watched = latest.watchers.load(Ordering::Acquire) > 0;
                if watched && following.is_none() {
                    following = latest.lock_ports().take();
                    if let Some(p) = &following {
                        if let Err(e) = p.refresh(&latest.tx) {
                            tracing::error!(error = %e, "vehicle subscriptions failed");
                            break;
                        }
                    }
                } else if !watched && following.is_some() {
                    *latest.lock_ports() = following.take();
                }
                let follow = async {
                    match following.as_mut() {
                        Some(p) => p.next(&latest.tx).await,
                        None => std::future::pending().await,
                    }
                };
                tokio::select! {
                    _ = shutdown.cancelled() => break,
                    _ = latest.watchers_changed.notified() => {}
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
                    r = follow => if let Err((what, e)) = r {
                        tracing::error!(error = %e, "{what} subscription failed");
                        break;
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

    /// The latest samples (a copy): the newest ones on the bus at this moment.
    pub fn snapshot(&self) -> Snapshot {
        // Unwatched, the subscriptions are here and read now; watched, the bus task
        // keeps the watch current.
        if let Some(p) = self.latest.lock_ports().as_ref() {
            if let Err(e) = p.refresh(&self.latest.tx) {
                tracing::warn!(error = %e, "cannot read the vehicle subscriptions");
            }
        }
        *self.snapshot.borrow()
    }

    /// Changes of the latest samples, each as it arrives while the [`Watch`] lives.
    pub fn watch(&self) -> Watch {
        if self.latest.watchers.fetch_add(1, Ordering::AcqRel) == 0 {
            self.latest.watchers_changed.notify_one();
        }
        // Start from the newest samples (the bus task may not be following yet).
        let _ = self.snapshot();
        Watch {
            rx: self.snapshot.clone(),
            latest: self.latest.clone(),
        }
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
    /// (or accepted-limited), else the failure. An emergency stop waits
    /// `stop_ack_timeout`, every other command `ack_timeout`.
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
        let wait = if matches!(command, Command::EmergencyStop) {
            self.stop_ack_timeout
        } else {
            self.ack_timeout
        };
        match tokio::time::timeout(wait, rx).await {
            Ok(Ok(ack)) if ack.is_accepted() => Ok(ack),
            Ok(Ok(ack)) => Err(CommandFailure::Refused(ack)),
            Ok(Err(_)) | Err(_) => {
                self.lock_pending().remove(&id);
                Err(CommandFailure::NoAck(wait))
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

impl Latest {
    fn lock_ports(&self) -> std::sync::MutexGuard<'_, Option<LatestPorts>> {
        self.ports.lock().unwrap_or_else(|p| p.into_inner())
    }
}
