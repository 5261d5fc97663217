//! Every bus call of groundcontrol-gateway: the four swarm topics, typed.
//!
//! | topic | direction | type | who in the gateway |
//! |---|---|---|---|
//! | `skymesh/swarm/command` | publish | `SwarmCommand` | every session (shared publisher) |
//! | `skymesh/swarm/reply` | subscribe | `SwarmReply` | the hub, which routes to clients |
//! | `skymesh/swarm/state` | subscribe (latest value) | `SwarmState` | the pose broadcast |
//! | `skymesh/swarm/watch` | publish | `SwarmWatch` | the pose broadcast: whether it reads the state |

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use anyhow::Context as _;
use skymesh_ipc_types::{topics, SwarmCommand, SwarmReply, SwarmState, SwarmWatch};
use skymesh_runtime::{Bus, IpcError, Publisher, Subscriber};

/// The `swarm_command` publisher, shared by every session, and the gateway's
/// request numbering.
///
/// One publisher per gateway; the sessions hold its mutex only for the copy into
/// shared memory.
#[derive(Debug, Clone)]
pub struct Commands {
    publisher: Arc<Mutex<Publisher<SwarmCommand>>>,
    next_request: Arc<AtomicU32>,
}

impl Commands {
    /// Whether a swarm queue reads the command topic: the only one that answers
    /// a command.
    pub fn queue_reads(&self) -> bool {
        self.publisher
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .subscribers()
            > 0
    }

    /// Numbers `cmd` (request ids are unique per gateway run, never 0) and publishes
    /// it. Returns the request id.
    pub fn publish(&self, mut cmd: SwarmCommand) -> Result<u32, IpcError> {
        let mut id = self.next_request.fetch_add(1, Ordering::Relaxed);
        if id == 0 {
            id = self.next_request.fetch_add(1, Ordering::Relaxed);
        }
        cmd.request_id = id;
        self.publisher
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .publish(cmd)?;
        Ok(id)
    }
}

/// The gateway's ports.
#[derive(Debug)]
pub struct Ports {
    pub commands: Commands,
    /// The queue's answers; the hub routes them to the clients.
    pub replies: Subscriber<SwarmReply>,
    /// Every drone's state; the pose broadcast reads the latest.
    pub state: Subscriber<SwarmState>,
    /// The pose broadcast's word that it reads the state at the queue's rate.
    pub watch: Publisher<SwarmWatch>,
}

impl Ports {
    pub fn open(bus: &Bus) -> anyhow::Result<Ports> {
        Ok(Ports {
            commands: Commands {
                publisher: Arc::new(Mutex::new(
                    bus.publisher::<SwarmCommand>(&topics::swarm_command())
                        .context("opening the swarm_command topic")?,
                )),
                next_request: Arc::new(AtomicU32::new(1)),
            },
            replies: bus
                .subscriber::<SwarmReply>(&topics::swarm_reply())
                .context("opening the swarm_reply topic")?,
            state: {
                let mut state = bus
                    .subscriber::<SwarmState>(&topics::swarm_state())
                    .context("opening the swarm_state topic")?;
                // The broadcast sends the newest; one it never read (it slept
                // while no destination listened) is not lost.
                state.set_newest_only();
                state
            },
            watch: bus
                .publisher::<SwarmWatch>(&topics::swarm_watch())
                .context("opening the swarm_watch topic")?,
        })
    }
}
