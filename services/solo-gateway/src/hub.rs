//! The one task that owns the app slot: accepts connections (one app at a time),
//! routes the shot engine's messages to the connected app, and publishes the
//! `AppSession` on every change and periodically.
//!
//! Sessions publish their app's messages themselves; they report here only when
//! they end. The follow stream reads who is connected from a `watch` channel.

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::ShotEventSample;
use skymesh_runtime::timer::Ticker;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::config::Settings;
use crate::drops::Drops;
use crate::ipc::Ports;
use crate::metrics::{ConnectionResult, Malformed, ToAppDrop};
use crate::session::{self, End, Outgoing, SessionCtx};

/// How long a rejected second phone gets to read its notification and close.
const REJECT_LINGER: Duration = Duration::from_secs(2);
/// After a failed `accept` (out of file descriptors, ...), wait this long.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// Who is connected, for the follow stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AppAddr {
    pub session: u32,
    pub ip: IpAddr,
}

/// What the hub hears from the other tasks.
#[derive(Debug)]
pub enum Event {
    /// A session task ended.
    Ended { session: u32, end: End },
    /// A task cannot go on (the bus failed): the service stops with this error.
    Fatal(anyhow::Error),
}

/// What to do with a new connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admission {
    Accept,
    /// The connected app's address again: close the old connection, take the new one.
    Replace,
    /// Another address while an app is connected: SECOND_PHONE_NOTIFICATION, close.
    Reject,
}

/// The one-app rule (pure). Addresses compare by IP only, IPv4-mapped IPv6 as IPv4.
pub fn admit(connected: Option<IpAddr>, peer: IpAddr) -> Admission {
    match connected {
        None => Admission::Accept,
        Some(ip) if ip.to_canonical() == peer.to_canonical() => Admission::Replace,
        Some(_) => Admission::Reject,
    }
}

#[derive(Debug)]
struct App {
    session: u32,
    peer: SocketAddr,
    tx: mpsc::Sender<Outgoing>,
    cancel: CancellationToken,
}

#[derive(Debug)]
pub struct Hub {
    settings: Settings,
    ports: Ports,
    drops: Drops,
    app: Option<App>,
    /// The last session number handed out (0 = none yet).
    last_session: u32,
    last_peer: Option<SocketAddr>,
    app_watch: watch::Sender<Option<AppAddr>>,
    events: mpsc::Sender<Event>,
    /// Parent of every session's token.
    stop: CancellationToken,
    tracker: TaskTracker,
    warned_invalid: bool,
}

impl Hub {
    pub fn new(
        settings: Settings,
        ports: Ports,
        drops: Drops,
        app_watch: watch::Sender<Option<AppAddr>>,
        events: mpsc::Sender<Event>,
        stop: CancellationToken,
        tracker: TaskTracker,
    ) -> Hub {
        Hub {
            settings,
            ports,
            drops,
            app: None,
            last_session: 0,
            last_peer: None,
            app_watch,
            events,
            stop,
            tracker,
            warned_invalid: false,
        }
    }

    /// Runs until `shutdown` or a fatal error; then closes the app's connection.
    pub async fn run(
        &mut self,
        listener: TcpListener,
        mut events: mpsc::Receiver<Event>,
        shutdown: &CancellationToken,
    ) -> anyhow::Result<()> {
        // On the machine-wide grid (skymesh_runtime::timer), not tokio's wheel: the
        // session goes out on the instants of the services' heartbeats, so neither
        // this process nor the shot engine, which listens to it, wakes for it alone
        // (a tokio interval would add two wake-ups a second of its own).
        let mut tick =
            Ticker::new(self.settings.session_publish).context("creating the session timer")?;
        let result = loop {
            let step = tokio::select! {
                biased;
                _ = shutdown.cancelled() => break Ok(()),
                event = events.recv() => match event {
                    Some(Event::Ended { session, end }) => self.on_ended(session, end),
                    Some(Event::Fatal(e)) => Err(e),
                    // The hub holds a sender itself; unreachable, but not worth a panic.
                    None => Ok(()),
                },
                accepted = listener.accept() => match accepted {
                    Ok((stream, peer)) => self.on_accept(stream, peer),
                    Err(e) => {
                        tracing::warn!(error = %e, "accepting a Solo app connection failed");
                        tokio::time::sleep(ACCEPT_BACKOFF).await;
                        Ok(())
                    }
                },
                sample = self.ports.to_app.recv() => match sample {
                    Ok(m) => self.on_to_app(&m),
                    Err(e) => Err(e.into()),
                },
                r = tick.tick() => match r {
                    Ok(_) => self.publish_session(),
                    Err(e) => Err(anyhow::Error::new(e).context("the session timer")),
                },
            };
            if let Err(e) = step {
                break Err(e);
            }
        };
        if self.app.is_some() {
            if let Err(e) = self.close_app("the gateway is stopping") {
                tracing::warn!(error = %e, "publishing the final app session failed");
            }
        }
        result
    }

    fn publish_session(&mut self) -> anyhow::Result<()> {
        let connected = self.app.is_some();
        self.ports
            .publish_session(self.last_session, connected, self.last_peer)?;
        Ok(())
    }

    fn on_accept(&mut self, stream: TcpStream, peer: SocketAddr) -> anyhow::Result<()> {
        let metrics = self.drops.metrics().clone();
        match admit(self.app.as_ref().map(|a| a.peer.ip()), peer.ip()) {
            Admission::Reject => {
                metrics.connection(ConnectionResult::RejectedSecondPhone);
                tracing::info!(
                    %peer,
                    app = ?self.app.as_ref().map(|a| a.peer),
                    "second phone rejected: an app from another address is connected"
                );
                self.tracker
                    .spawn(session::reject_second_phone(stream, REJECT_LINGER));
                return Ok(());
            }
            Admission::Replace => {
                metrics.connection(ConnectionResult::Replaced);
                self.close_app("replaced by a new connection from the same address")?;
            }
            Admission::Accept => metrics.connection(ConnectionResult::Accepted),
        }
        if let Err(e) = stream.set_nodelay(true) {
            tracing::debug!(%peer, error = %e, "cannot set TCP_NODELAY");
        }
        self.last_session = self.last_session.checked_add(1).unwrap_or(1);
        self.last_peer = Some(peer);
        let session = self.last_session;
        let (tx, rx) = mpsc::channel(self.settings.outgoing_queue);
        let cancel = self.stop.child_token();
        let ctx = SessionCtx {
            session,
            peer,
            frame_timeout: self.settings.frame_timeout,
            backend_wait: self.settings.backend_wait,
            from_app: self.ports.from_app.clone(),
            drops: self.drops.clone(),
            replies: tx.clone(),
            rate: (
                self.settings.max_messages_per_s,
                self.settings.message_burst,
            ),
        };
        let events = self.events.clone();
        let token = cancel.clone();
        self.tracker.spawn(async move {
            let end = session::run(stream, ctx, rx, token).await;
            let _ = events.send(Event::Ended { session, end }).await;
        });
        self.app = Some(App {
            session,
            peer,
            tx,
            cancel,
        });
        metrics.clients_connected.set(1.0);
        self.app_watch.send_replace(Some(AppAddr {
            session,
            ip: peer.ip().to_canonical(),
        }));
        tracing::info!(%peer, session, "Solo app connected");
        self.publish_session()
    }

    /// Closes the connected app's connection and tells the engine.
    fn close_app(&mut self, why: &str) -> anyhow::Result<()> {
        let Some(app) = self.app.take() else {
            return Ok(());
        };
        app.cancel.cancel();
        self.drops.metrics().clients_connected.set(0.0);
        self.app_watch.send_replace(None);
        tracing::info!(peer = %app.peer, session = app.session, reason = why, "Solo app disconnected");
        self.ports
            .publish_session(app.session, false, Some(app.peer))?;
        Ok(())
    }

    fn on_ended(&mut self, session: u32, end: End) -> anyhow::Result<()> {
        if let End::Bus(e) = end {
            return Err(anyhow::Error::new(e).context("publishing an app message"));
        }
        if self.app.as_ref().is_some_and(|a| a.session == session) {
            self.close_app(&end.to_string())?;
        } else {
            tracing::debug!(session, end = %end, "an earlier session ended");
        }
        Ok(())
    }

    fn on_to_app(&mut self, m: &ShotEventSample) -> anyhow::Result<()> {
        let metrics = self.drops.metrics();
        let Some(app) = &self.app else {
            metrics.to_app_dropped(ToAppDrop::NoApp);
            tracing::debug!(
                kind = m.kind,
                "message for the app dropped: no app connected"
            );
            return Ok(());
        };
        if m.session != 0 && m.session != app.session {
            metrics.to_app_dropped(ToAppDrop::StaleSession);
            tracing::debug!(
                kind = m.kind,
                to = m.session,
                connected = app.session,
                "message for an earlier app session dropped"
            );
            return Ok(());
        }
        // The event as the Solo message that tells it, checked the way the app
        // will read it.
        let msg = match m.event() {
            Ok(event) => {
                let msg = crate::translate::event(&event);
                msg.validate().map(|()| msg).map_err(|e| e.to_string())
            }
            Err(e) => Err(e.to_string()),
        };
        let msg = match msg {
            Ok(msg) => msg,
            Err(e) => {
                metrics.to_app_dropped(ToAppDrop::Invalid);
                if !std::mem::replace(&mut self.warned_invalid, true) {
                    tracing::warn!(error = %e, "the shot engine sent an event that does not translate; dropped (further ones at debug)");
                } else {
                    tracing::debug!(error = %e, "untranslatable event for the app dropped");
                }
                return Ok(());
            }
        };
        let out = Outgoing {
            msg_type: msg.msg_type(),
            frame: msg.to_bytes(),
        };
        match app.tx.try_send(out) {
            Ok(()) => Ok(()),
            Err(mpsc::error::TrySendError::Full(_)) => {
                let why = format!(
                    "outgoing queue of {} frames full: the app stopped reading",
                    self.settings.outgoing_queue
                );
                self.drops.record(Malformed::Overflow, app.peer, &why);
                self.close_app(&why)
            }
            Err(mpsc::error::TrySendError::Closed(_)) => {
                metrics.to_app_dropped(ToAppDrop::NoApp);
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_app_at_a_time() {
        let a: IpAddr = "127.0.0.1".parse().unwrap();
        let b: IpAddr = "127.0.0.2".parse().unwrap();
        let a6: IpAddr = "::ffff:127.0.0.1".parse().unwrap();
        assert_eq!(admit(None, a), Admission::Accept);
        assert_eq!(admit(Some(a), a), Admission::Replace);
        assert_eq!(admit(Some(a6), a), Admission::Replace);
        assert_eq!(admit(Some(a), b), Admission::Reject);
    }
}
