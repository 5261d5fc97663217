//! The one task that owns the client table: accepts connections (at most
//! `max_clients`), numbers them, and routes the swarm queue's replies to the
//! client whose command they answer.
//!
//! Sessions publish their commands themselves; they report here only when they end.
//! The hub never waits on a client: a reply goes into the client's bounded queue
//! with `try_send`, and a client whose queue is full is closed.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::Duration;

use gc_proto::Record;
use skymesh_ipc_types::{SwarmCommandKind, SwarmReply, SwarmResult, ALL_DRONES};
use skymesh_runtime::Subscriber;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::config::Settings;
use crate::drops::Drops;
use crate::ipc::Commands;
use crate::metrics::{ConnectionResult, DisconnectReason, ReplyDrop};
use crate::session::{self, End, Limits, SessionCtx};

/// After a failed `accept` (out of file descriptors, ...), wait this long.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// What the hub hears from the sessions.
#[derive(Debug)]
pub struct Ended {
    pub client: u16,
    pub end: End,
}

#[derive(Debug)]
struct Client {
    peer: SocketAddr,
    tx: mpsc::Sender<Record>,
    cancel: CancellationToken,
}

/// Geofence commands: a refusal (the arbiter refused the box, or did not take it)
/// is answered ACK_CMD_TIMEOUT, the protocol's one failure record, so the client
/// never believes a fence is in force that is not.
fn refusal_answered(kind: u8) -> bool {
    matches!(
        SwarmCommandKind::try_from(kind),
        Ok(SwarmCommandKind::SetGeofence
            | SwarmCommandKind::ReconfigureGeofence
            | SwarmCommandKind::SetGeofencePosition)
    )
}

/// The record a reply becomes for the client, if any. `ALL_DRONES` is context −1.
/// GroundControl has no record for a refusal: it is only logged, except for the
/// geofence commands ([`refusal_answered`]).
pub fn reply_record(reply: &SwarmReply, result: SwarmResult) -> Option<Record> {
    let drone = if reply.drone == ALL_DRONES {
        -1
    } else {
        i32::from(reply.drone)
    };
    let kind = i32::from(reply.kind);
    match result {
        SwarmResult::Success => Some(Record::ack(true, drone, kind)),
        SwarmResult::Timeout => Some(Record::ack(false, drone, kind)),
        SwarmResult::Refused if refusal_answered(reply.kind) => {
            Some(Record::ack(false, drone, kind))
        }
        SwarmResult::IdleState => Some(Record::idle_state(drone, reply.value != 0)),
        SwarmResult::Refused | SwarmResult::Accepted => None,
    }
}

#[derive(Debug)]
pub struct Hub {
    settings: Settings,
    commands: Commands,
    replies: Subscriber<SwarmReply>,
    drops: Drops,
    clients: HashMap<u16, Client>,
    /// The last connection id handed out.
    last_client: u16,
    events: mpsc::Sender<Ended>,
    /// Parent of every session's token.
    stop: CancellationToken,
    tracker: TaskTracker,
}

impl Hub {
    pub fn new(
        settings: Settings,
        commands: Commands,
        replies: Subscriber<SwarmReply>,
        drops: Drops,
        events: mpsc::Sender<Ended>,
        stop: CancellationToken,
        tracker: TaskTracker,
    ) -> Hub {
        Hub {
            settings,
            commands,
            replies,
            drops,
            clients: HashMap::new(),
            last_client: 0,
            events,
            stop,
            tracker,
        }
    }

    /// Runs until `shutdown` or a fatal error, then closes every client.
    pub async fn run(
        &mut self,
        listener: TcpListener,
        mut ended: mpsc::Receiver<Ended>,
        shutdown: &CancellationToken,
    ) -> anyhow::Result<()> {
        let result = loop {
            let step = tokio::select! {
                biased;
                _ = shutdown.cancelled() => break Ok(()),
                event = ended.recv() => match event {
                    Some(e) => self.on_ended(e),
                    // The hub holds a sender itself; unreachable.
                    None => Ok(()),
                },
                reply = self.replies.recv() => match reply {
                    Ok(r) => {
                        self.on_reply(&r);
                        Ok(())
                    }
                    Err(e) => Err(anyhow::Error::new(e).context("receiving swarm replies")),
                },
                accepted = listener.accept() => {
                    match accepted {
                        Ok((stream, peer)) => self.on_accept(stream, peer),
                        Err(e) => {
                            tracing::warn!(error = %e, "accepting a GroundControl client failed");
                            tokio::time::sleep(ACCEPT_BACKOFF).await;
                        }
                    }
                    Ok(())
                },
            };
            if let Err(e) = step {
                break Err(e);
            }
        };
        for (_, c) in self.clients.drain() {
            c.cancel.cancel();
        }
        self.drops.metrics().clients.set(0.0);
        result
    }

    fn next_client_id(&mut self) -> u16 {
        loop {
            self.last_client = self.last_client.wrapping_add(1);
            if self.last_client != 0 && !self.clients.contains_key(&self.last_client) {
                return self.last_client;
            }
        }
    }

    fn on_accept(&mut self, stream: TcpStream, peer: SocketAddr) {
        let metrics = self.drops.metrics().clone();
        if self.clients.len() >= self.settings.max_clients {
            metrics.connection(ConnectionResult::RefusedMaxClients);
            if let Some(hidden) = self.drops.allow("max_clients") {
                tracing::warn!(
                    %peer,
                    max_clients = self.settings.max_clients,
                    similar_since_last_warning = hidden,
                    "GroundControl client refused: max_clients are connected"
                );
            }
            drop(stream);
            return;
        }
        metrics.connection(ConnectionResult::Accepted);
        if let Err(e) = stream.set_nodelay(true) {
            tracing::debug!(%peer, error = %e, "cannot set TCP_NODELAY");
        }
        let client = self.next_client_id();
        let privileged = self.settings.is_privileged(peer.ip());
        let (tx, rx) = mpsc::channel(self.settings.outgoing_queue);
        let cancel = self.stop.child_token();
        let ctx = SessionCtx {
            client,
            peer,
            privileged,
            commands: self.commands.clone(),
            drops: self.drops.clone(),
            replies: tx.clone(),
            limits: Limits::of(&self.settings),
        };
        let events = self.events.clone();
        let token = cancel.clone();
        self.tracker.spawn(async move {
            let end = session::run(stream, ctx, rx, token).await;
            let _ = events.send(Ended { client, end }).await;
        });
        self.clients.insert(client, Client { peer, tx, cancel });
        metrics.clients.set(self.clients.len() as f64);
        tracing::info!(%peer, client, privileged, "GroundControl client connected");
    }

    fn remove(&mut self, client: u16, reason: DisconnectReason, why: &dyn std::fmt::Display) {
        if let Some(c) = self.clients.remove(&client) {
            c.cancel.cancel();
            let metrics = self.drops.metrics();
            metrics.disconnect(reason);
            metrics.clients.set(self.clients.len() as f64);
            tracing::info!(peer = %c.peer, client, reason = %why, "GroundControl client disconnected");
        }
    }

    fn on_ended(&mut self, e: Ended) -> anyhow::Result<()> {
        if let End::Bus(err) = e.end {
            return Err(anyhow::Error::new(err).context("publishing a swarm command"));
        }
        if let End::Truncated(n) = e.end {
            tracing::debug!(
                client = e.client,
                bytes = n,
                "partial record dropped at disconnect"
            );
        }
        self.remove(e.client, e.end.reason(), &e.end);
        Ok(())
    }

    fn on_reply(&mut self, reply: &SwarmReply) {
        let metrics = self.drops.metrics().clone();
        let Ok(result) = reply.result() else {
            metrics.reply_dropped(ReplyDrop::Invalid);
            tracing::debug!(
                result = reply.result,
                "swarm reply with an unknown result dropped"
            );
            return;
        };
        let Some(client) = self.clients.get(&reply.client) else {
            metrics.reply_dropped(ReplyDrop::ClientGone);
            tracing::debug!(
                client = reply.client,
                request_id = reply.request_id,
                result = result.as_str(),
                "swarm reply for a client that is not connected dropped"
            );
            return;
        };
        metrics.queue_reply(result.as_str());
        let Some(record) = reply_record(reply, result) else {
            if result == SwarmResult::Refused {
                let level_warn = self.drops.allow("queue_refused");
                let (drone, kind, reason) = (reply.drone, reply.kind, reply.reason.as_str());
                match level_warn {
                    Some(hidden) => {
                        tracing::info!(
                        client = reply.client, request_id = reply.request_id, drone, kind, reason,
                        similar_since_last_message = hidden,
                        "the swarm queue refused a command (GroundControl has no record for this)"
                    )
                    }
                    None => tracing::debug!(
                        client = reply.client,
                        request_id = reply.request_id,
                        drone,
                        kind,
                        reason,
                        "the swarm queue refused a command"
                    ),
                }
            }
            return;
        };
        match client.tx.try_send(record) {
            Ok(()) => {}
            Err(mpsc::error::TrySendError::Full(_)) => {
                metrics.reply_dropped(ReplyDrop::Overflow);
                let why = format!(
                    "outgoing queue of {} records full: the client stopped reading",
                    self.settings.outgoing_queue
                );
                self.remove(reply.client, DisconnectReason::Overflow, &why);
            }
            Err(mpsc::error::TrySendError::Closed(_)) => {
                metrics.reply_dropped(ReplyDrop::ClientGone);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gc_proto::NetCmdType;

    #[test]
    fn replies_become_records() {
        let r = SwarmReply {
            drone: 4,
            kind: 0xA6,
            value: 1,
            ..SwarmReply::default()
        };
        let ack = reply_record(&r, SwarmResult::Success).unwrap();
        assert_eq!(ack.net_type(), Some(NetCmdType::AckCmdSuccess));
        assert_eq!((ack.context, ack.int1), (4, 0xA6));
        let t = reply_record(&r, SwarmResult::Timeout).unwrap();
        assert_eq!(t.net_type(), Some(NetCmdType::AckCmdTimeout));
        let idle = reply_record(&r, SwarmResult::IdleState).unwrap();
        assert_eq!(idle.net_type(), Some(NetCmdType::CmdExtCheckAllIdle));
        assert_eq!((idle.context, idle.int1), (4, 1));
        assert!(reply_record(&r, SwarmResult::Refused).is_none());
        assert!(reply_record(&r, SwarmResult::Accepted).is_none());
        for kind in [
            SwarmCommandKind::SetGeofence,
            SwarmCommandKind::ReconfigureGeofence,
            SwarmCommandKind::SetGeofencePosition,
        ] {
            let fence = SwarmReply {
                kind: kind.to_wire(),
                ..r
            };
            let refused = reply_record(&fence, SwarmResult::Refused).unwrap();
            assert_eq!(
                refused.net_type(),
                Some(NetCmdType::AckCmdTimeout),
                "{kind}"
            );
            assert_eq!(
                (refused.context, refused.int1),
                (4, i32::from(kind.to_wire()))
            );
        }
        let all = SwarmReply {
            drone: ALL_DRONES,
            ..r
        };
        assert_eq!(
            reply_record(&all, SwarmResult::Success).unwrap().context,
            -1
        );
    }
}
