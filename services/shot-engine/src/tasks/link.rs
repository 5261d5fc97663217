//! The task runner's bus side: the latest vehicle samples, read when asked, and
//! `VehicleCommand`s published as the requester's source with their `CommandAck`
//! awaited.
//!
//! The runner commands as the gateway that asked (its [`CommandSource`]), so the
//! arbiter's authority and refusals are the gateway's own. The gateway numbers its
//! own commands from 1; the runner's command ids start at [`FIRST_ID`] so the two
//! never answer each other's acks.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/vehicle/{id}/command` | publish | `VehicleCommand` (the request's source) |
//! | `skymesh/vehicle/{id}/command_ack` | subscribe | `CommandAck` |
//! | `skymesh/vehicle/{id}/{state,status,payload,authority}` | subscribe | latest samples |

use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, AuthorityState, Command, CommandAck, CommandError, CommandSource, PayloadState,
    TaskResult, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_ipc_types::{AuthorityDomain, RefusalReason};
use skymesh_runtime::{Bus, CancellationToken, Publisher, Subscriber};
use tokio::sync::oneshot;

/// The runner's first command id (see the module docs).
pub const FIRST_ID: u32 = 0x8000_0000;

/// The latest sample of each vehicle topic (`None` until the first arrives), seen
/// by a task flying as `source`.
#[derive(Debug, Clone, Copy)]
pub struct Snapshot {
    pub state: Option<VehicleState>,
    pub status: Option<VehicleStatus>,
    pub payload: Option<PayloadState>,
    pub authority: Option<AuthorityState>,
    pub source: CommandSource,
}

impl Snapshot {
    /// Nothing received yet, for `source`.
    pub fn empty(source: CommandSource) -> Self {
        Snapshot {
            state: None,
            status: None,
            payload: None,
            authority: None,
            source,
        }
    }

    /// True when the arbiter says `source` holds flight authority.
    pub fn holds_flight(&self) -> bool {
        self.authority.and_then(|a| a.flight()) == Some(self.source)
    }

    /// True when the arbiter says `source` holds payload authority.
    pub fn holds_payload(&self) -> bool {
        self.authority.and_then(|a| a.payload()) == Some(self.source)
    }
}

/// Why a command did not succeed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandFailure {
    #[error("invalid command: {0}")]
    Invalid(#[from] CommandError),
    #[error("bus: {0}")]
    Bus(String),
    #[error("no acknowledgement within {0:?}")]
    NoAck(Duration),
    #[error("refused: {}", .0.detail)]
    Refused(CommandAck),
}

impl CommandFailure {
    /// The result a request reports for this failure of `command`.
    pub fn result(&self, command: &Command) -> TaskResult {
        let domain = command.kind().authority();
        match self {
            CommandFailure::Invalid(_) => TaskResult::InvalidParameter,
            CommandFailure::Bus(_) => TaskResult::Internal,
            CommandFailure::NoAck(_) => TaskResult::VehicleUnavailable,
            CommandFailure::Refused(ack) => match ack.reason() {
                Some(RefusalReason::NoAuthority | RefusalReason::Preempted) => match domain {
                    Some(AuthorityDomain::Payload) => TaskResult::NoPayloadAuthority,
                    _ => TaskResult::NoFlightAuthority,
                },
                Some(RefusalReason::LinkDown | RefusalReason::Timeout) => {
                    TaskResult::VehicleUnavailable
                }
                Some(RefusalReason::WrongState) => TaskResult::WrongState,
                Some(RefusalReason::InvalidParameter) => TaskResult::InvalidParameter,
                Some(RefusalReason::Unsupported) if domain == Some(AuthorityDomain::Payload) => {
                    TaskResult::PayloadUnsupported
                }
                _ => TaskResult::Refused,
            },
        }
    }
}

type Pending = Arc<Mutex<HashMap<(u8, u32), oneshot::Sender<CommandAck>>>>;

#[derive(Debug)]
struct Latest {
    state: Subscriber<VehicleState>,
    status: Subscriber<VehicleStatus>,
    payload: Subscriber<PayloadState>,
    authority: Subscriber<AuthorityState>,
    last: Snapshot,
}

/// Cheap to clone; every clone talks to the same ports.
#[derive(Debug, Clone)]
pub struct VehicleLink {
    vehicle_id: u8,
    commands: Arc<Mutex<Publisher<VehicleCommand>>>,
    next_id: Arc<AtomicU32>,
    pending: Pending,
    latest: Arc<Mutex<Latest>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl VehicleLink {
    /// Opens the ports and starts the task that hands acks to their waiters (it
    /// ends with `shutdown`).
    pub fn open(bus: &Bus, vehicle_id: u8, shutdown: CancellationToken) -> anyhow::Result<Self> {
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
        let authority = bus
            .subscriber::<AuthorityState>(&topics::vehicle_authority(vehicle_id))
            .context("opening the authority topic")?;
        // Read newest-first when asked: overwritten samples are by design.
        state.set_newest_only();
        status.set_newest_only();
        payload.set_newest_only();
        let pending: Pending = Arc::default();
        let link = VehicleLink {
            vehicle_id,
            commands: Arc::new(Mutex::new(commands)),
            next_id: Arc::new(AtomicU32::new(FIRST_ID)),
            pending: pending.clone(),
            latest: Arc::new(Mutex::new(Latest {
                state,
                status,
                payload,
                authority,
                last: Snapshot::empty(CommandSource::DjiDrc),
            })),
        };
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = shutdown.cancelled() => break,
                    r = acks.recv() => match r {
                        Ok(ack) => {
                            let waiter = lock(&pending).remove(&(ack.source, ack.command_id));
                            if let Some(w) = waiter {
                                let _ = w.send(ack);
                            }
                        }
                        Err(e) => {
                            tracing::error!(error = %e, "task runner: command ack subscription failed");
                            break;
                        }
                    },
                }
            }
        });
        Ok(link)
    }

    /// The newest samples on the bus now, as `source` sees them.
    pub fn snapshot(&self, source: CommandSource) -> Snapshot {
        let mut l = lock(&self.latest);
        let read = (
            l.state.latest(),
            l.status.latest(),
            l.payload.latest(),
            l.authority.latest(),
        );
        match read {
            (Ok(state), Ok(status), Ok(payload), Ok(authority)) => {
                let last = &mut l.last;
                last.state = state.or(last.state);
                last.status = status.or(last.status);
                last.payload = payload.or(last.payload);
                last.authority = authority.or(last.authority);
            }
            _ => tracing::warn!("task runner: cannot read the vehicle subscriptions"),
        }
        Snapshot { source, ..l.last }
    }

    /// Publishes `command` as `source` (max age `max_age_ms`, 0 = the arbiter's
    /// default) without waiting for its ack.
    pub fn send(
        &self,
        source: CommandSource,
        command: &Command,
        max_age_ms: u32,
    ) -> Result<u32, CommandFailure> {
        let id = self.next_id();
        self.publish(source, id, command, max_age_ms)?;
        Ok(id)
    }

    /// Publishes `command` as `source` and waits at most `ack_timeout` for its
    /// `CommandAck`: `Ok(ack)` when accepted, else the failure.
    pub async fn command(
        &self,
        source: CommandSource,
        command: &Command,
        ack_timeout: Duration,
    ) -> Result<CommandAck, CommandFailure> {
        let id = self.next_id();
        let key = (source.to_wire(), id);
        let (tx, rx) = oneshot::channel();
        lock(&self.pending).insert(key, tx);
        if let Err(e) = self.publish(source, id, command, 0) {
            lock(&self.pending).remove(&key);
            return Err(e);
        }
        match tokio::time::timeout(ack_timeout, rx).await {
            Ok(Ok(ack)) if ack.is_accepted() => Ok(ack),
            Ok(Ok(ack)) => Err(CommandFailure::Refused(ack)),
            Ok(Err(_)) | Err(_) => {
                lock(&self.pending).remove(&key);
                Err(CommandFailure::NoAck(ack_timeout))
            }
        }
    }

    fn next_id(&self) -> u32 {
        // Wraps back into the runner's half of the id space.
        self.next_id.fetch_add(1, Ordering::Relaxed) | FIRST_ID
    }

    fn publish(
        &self,
        source: CommandSource,
        id: u32,
        command: &Command,
        max_age_ms: u32,
    ) -> Result<(), CommandFailure> {
        let mut sample = VehicleCommand::new(self.vehicle_id, source, id, command)?;
        sample.max_age_ms = max_age_ms;
        lock(&self.commands)
            .publish(sample)
            .map(|_| ())
            .map_err(|e| CommandFailure::Bus(e.to_string()))
    }
}

/// One task's side of the link: the requester's source and command timeout.
#[derive(Debug, Clone)]
pub struct TaskLink {
    pub link: VehicleLink,
    pub source: CommandSource,
    pub ack_timeout: Duration,
}

impl TaskLink {
    pub fn snapshot(&self) -> Snapshot {
        self.link.snapshot(self.source)
    }

    pub fn send(&self, command: &Command, max_age_ms: u32) -> Result<u32, CommandFailure> {
        self.link.send(self.source, command, max_age_ms)
    }

    /// Sends `commands` one after the other, each after the previous one's
    /// acceptance: `Ok` when all were accepted, else the first failure's result
    /// (logged with `what`).
    pub async fn run(&self, what: &str, commands: &[Command]) -> TaskResult {
        for c in commands {
            if let Err(f) = self.link.command(self.source, c, self.ack_timeout).await {
                let r = f.result(c);
                tracing::info!(what, command = ?c.kind(), error = %f, result = %r, "command not accepted");
                return r;
            }
        }
        TaskResult::Ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::AckResult;

    fn refused(reason: RefusalReason) -> CommandFailure {
        CommandFailure::Refused(CommandAck {
            result: AckResult::Refused.to_wire(),
            reason: reason.to_wire(),
            ..Default::default()
        })
    }

    #[test]
    fn failures_map_to_results() {
        let brake = Command::Brake;
        let capture = Command::CameraCapture;
        assert_eq!(
            refused(RefusalReason::NoAuthority).result(&brake),
            TaskResult::NoFlightAuthority
        );
        assert_eq!(
            refused(RefusalReason::NoAuthority).result(&capture),
            TaskResult::NoPayloadAuthority
        );
        assert_eq!(
            refused(RefusalReason::Geofence).result(&brake),
            TaskResult::Refused
        );
        assert_eq!(
            refused(RefusalReason::LinkDown).result(&brake),
            TaskResult::VehicleUnavailable
        );
        assert_eq!(
            refused(RefusalReason::WrongState).result(&brake),
            TaskResult::WrongState
        );
        assert_eq!(
            CommandFailure::NoAck(Duration::from_secs(1)).result(&brake),
            TaskResult::VehicleUnavailable
        );
        assert_eq!(
            CommandFailure::Invalid(CommandError::NotFinite { name: "x" }).result(&brake),
            TaskResult::InvalidParameter
        );
        assert_eq!(
            CommandFailure::Bus("x".into()).result(&brake),
            TaskResult::Internal
        );
    }

    #[test]
    fn ids_stay_in_the_runners_half() {
        let next = AtomicU32::new(u32::MAX);
        let id = next.fetch_add(1, Ordering::Relaxed) | FIRST_ID;
        assert_eq!(id, u32::MAX);
        let id = next.fetch_add(1, Ordering::Relaxed) | FIRST_ID;
        assert_eq!(id, FIRST_ID, "wrapped into the runner's half");
    }
}
