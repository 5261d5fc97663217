//! The gateway's one loop: MQTT events, replies and events from the tasks, DRC
//! notices and a tick → checks, dispatch, the outbox, the authority keep-alive.
//! The tick runs only when something needs it (see [`Gateway::next_tick`]): an idle
//! gateway wakes for MQTT and bus traffic alone.
//!
//! Inbound messages go through [`crate::inbound::classify`]: what cannot be replied
//! to is counted by kind and warned at most every 10 s per kind; a request refused
//! by `parse_service` is replied with its code; the rest goes to the [`Dispatcher`].

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use dji_proto::{
    encode_event, encode_services_reply, topic, DrcStatusNotify, JoystickInvalidNotify, TopicKind,
};
use rumqttc::{AsyncClient, QoS};
use serde_json::Value;
use skymesh_ipc_types::{AuthorityDomain, Command, ServiceState};
use skymesh_runtime::{Context, WarnLimiter};
use tokio::sync::mpsc;

use crate::config::Settings;
use crate::dispatch::Dispatcher;
use crate::drc::{Drc, DrcNotice};
use crate::inbound::{classify, Inbound};
use crate::link::VehicleLink;
use crate::metrics::{topic_label, Metrics};
use crate::mqtt::{self, MqttEvent};
use crate::outbox::{OutMessage, Outbox};
use crate::ratelimit::RateLimiter;
use crate::shared::{Emitter, Keep, Outgoing, Shared};
use crate::tasks::TaskClient;

/// Outbox draining, the authority keep-alive and the task gauges, while any of them
/// has something to do.
const TICK: Duration = Duration::from_millis(50);
/// The longest wait with nothing scheduled: a tick that finds nothing to do; only
/// bounds the wait, no deadline depends on it.
const IDLE_WAIT: Duration = Duration::from_secs(60);

/// Milliseconds since the Unix epoch (envelope timestamps).
pub fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// A fresh UUID (version 4 layout) for event tid/bid.
pub fn uuid() -> String {
    format!(
        "{:08x}-{:04x}-4{:03x}-{:04x}-{:012x}",
        fastrand::u32(..),
        fastrand::u16(..),
        fastrand::u16(..0x1000),
        (fastrand::u16(..) & 0x3fff) | 0x8000,
        fastrand::u64(..1 << 48),
    )
}

/// The loop's state.
struct Gateway {
    settings: Arc<Settings>,
    metrics: Metrics,
    dispatcher: Dispatcher,
    link: VehicleLink,
    keep: Arc<Keep>,
    client: AsyncClient,
    connected: bool,
    outbox: Outbox,
    limiter: RateLimiter<TopicKind>,
    warn: WarnLimiter<&'static str>,
}

impl Gateway {
    fn on_message(&mut self, topic_name: &str, payload: &[u8], now: Instant) {
        let (kind, inbound) = classify(
            &self.settings.gateway_sn,
            self.settings.limits.max_payload_bytes,
            &mut self.limiter,
            topic_name,
            payload,
            now,
        );
        if let Some(kind) = kind {
            self.metrics.message("in", kind);
        }
        match inbound {
            Inbound::Dropped { kind, detail } => self.drop_input(kind, detail, now),
            Inbound::RateLimited(kind) => {
                self.metrics.rate_limited(kind);
                if let Some(hidden) = self.warn.allow("rate_limited", now) {
                    tracing::warn!(
                        topic = topic_label(kind),
                        max_per_s = self.settings.limits.max_messages_per_s,
                        similar_since_last_warning = hidden,
                        "inbound rate exceeded: message dropped"
                    );
                }
            }
            Inbound::Request(env, Ok(req)) => {
                tracing::debug!(method = %env.method, tid = %env.tid, "request");
                self.dispatcher.handle(*env, *req);
            }
            Inbound::Request(env, Err(reject)) => {
                tracing::info!(method = %env.method, tid = %env.tid, result = reject.code, field = %reject.field, reason = %reject.reason, "request refused");
                self.push_reply(&env, reject.code, None);
            }
            Inbound::EventReply(Ok(r)) => match self.outbox.on_reply(&r.tid, &r.bid) {
                Some(method) => {
                    self.metrics.event_reply("matched");
                    tracing::debug!(method, tid = %r.tid, result = r.result, "event answered");
                }
                None => self.metrics.event_reply("unmatched"),
            },
            Inbound::EventReply(Err(reject)) => {
                self.metrics.event_reply("invalid");
                tracing::debug!(reason = %reject, "events_reply not understood");
            }
        }
    }

    /// Counts and logs (rate-limited) an input that gets no reply.
    fn drop_input(&mut self, kind: &'static str, detail: String, now: Instant) {
        self.metrics.malformed(kind);
        match self.warn.allow(kind, now) {
            Some(hidden) => tracing::warn!(
                kind,
                detail = %detail,
                similar_since_last_warning = hidden,
                "MQTT input dropped"
            ),
            None => tracing::debug!(kind, detail = %detail, "MQTT input dropped"),
        }
    }

    fn push(&mut self, m: OutMessage) {
        if let Some(dropped) = self.outbox.push(m) {
            self.lost(dropped);
        }
    }

    fn lost(&mut self, dropped: OutMessage) {
        self.metrics.outbox_dropped.inc();
        if let Some(hidden) = self.warn.allow("outbox_full", Instant::now()) {
            tracing::warn!(
                method = dropped.method,
                similar_since_last_warning = hidden,
                "outbound queue full while the broker is unreachable: oldest message dropped"
            );
        }
    }

    fn push_reply(&mut self, request: &dji_proto::Envelope, result: u32, output: Option<Value>) {
        self.metrics.request(&request.method, result);
        let payload =
            encode_services_reply(request, &self.settings.gateway_sn, result, output, now_ms());
        self.push(OutMessage {
            topic: TopicKind::ServicesReply,
            method: crate::metrics::method_label(&request.method),
            payload,
        });
    }

    fn on_outgoing(&mut self, o: Outgoing, now: Instant) {
        match o {
            Outgoing::Reply {
                request,
                result,
                output,
            } => self.push_reply(&request, result, output),
            Outgoing::Event {
                method,
                data,
                need_reply,
            } => {
                let (tid, bid) = (uuid(), uuid());
                let payload = encode_event(
                    &self.settings.gateway_sn,
                    method,
                    data,
                    need_reply,
                    &tid,
                    &bid,
                    now_ms(),
                );
                self.metrics.event(method);
                let m = OutMessage {
                    topic: TopicKind::Events,
                    method,
                    payload,
                };
                let dropped = if need_reply {
                    self.outbox.push_awaiting_reply(&tid, &bid, m, now)
                } else {
                    self.outbox.push(m)
                };
                if let Some(d) = dropped {
                    self.lost(d);
                }
            }
        }
    }

    fn on_notice(&mut self, n: DrcNotice, now: Instant) {
        let event = match n {
            DrcNotice::State { drc_state, result } => {
                tracing::info!(drc_state, result, "DRC state");
                Outgoing::Event {
                    method: "drc_status_notify",
                    data: serde_json::to_value(DrcStatusNotify { result, drc_state })
                        .unwrap_or_default(),
                    need_reply: true,
                }
            }
            DrcNotice::JoystickInvalid(reason) => {
                tracing::info!(?reason, "DRC flight control invalid");
                Outgoing::Event {
                    method: "joystick_invalid_notify",
                    data: serde_json::to_value(JoystickInvalidNotify {
                        reason: reason as u8,
                    })
                    .unwrap_or_default(),
                    need_reply: true,
                }
            }
        };
        self.on_outgoing(event, now);
    }

    /// Publishes what is queued while connected (QoS 1).
    fn drain(&mut self) {
        while self.connected {
            let Some(m) = self.outbox.pop() else { break };
            let t = topic(&self.settings.gateway_sn, m.topic);
            match self
                .client
                .try_publish(t, QoS::AtLeastOnce, false, m.payload.clone())
            {
                Ok(()) => self.metrics.message("out", m.topic),
                // The client's queue is full: flow control, try again next tick.
                Err(_) => {
                    self.outbox.unpop(m);
                    break;
                }
            }
        }
        self.metrics.queued.set(self.outbox.queued() as f64);
    }

    /// When [`Gateway::tick`] next has work: every [`TICK`] while the client's queue
    /// was full (retry the drain), while the cloud keeps an authority (keep-alive,
    /// loss detection) or while a flight task, POI or panorama runs (their gauges);
    /// else at the next event re-send (while connected); else not at all (`None`):
    /// what changes that arrives as an MQTT event, a task's message or a notice,
    /// after which this is asked again.
    fn next_tick(&self, now: Instant) -> Option<Instant> {
        let busy = (self.connected && self.outbox.queued() > 0)
            || self.keep.get(AuthorityDomain::Flight)
            || self.keep.get(AuthorityDomain::Payload)
            || self.dispatcher.task_active()
            || self.dispatcher.poi_active()
            || self.dispatcher.pano_active();
        if busy {
            return Some(now + TICK);
        }
        self.connected.then(|| self.outbox.next_resend()).flatten()
    }

    fn tick(&mut self, now: Instant) {
        if self.connected {
            let round = self.outbox.resend_due(now);
            self.metrics.event_resends.add(round.resent.len() as u64);
            for method in round.gave_up {
                self.metrics.event_reply_timeout(method);
                tracing::info!(
                    method,
                    "the cloud never answered an event (need_reply): gave up"
                );
            }
        }
        self.drain();
        self.keepalive();
        self.update_gauges();
    }

    fn update_gauges(&self) {
        self.metrics
            .task_active
            .set(f64::from(u8::from(self.dispatcher.task_active())));
        self.metrics
            .poi_active
            .set(f64::from(u8::from(self.dispatcher.poi_active())));
        self.metrics
            .panorama_active
            .set(f64::from(u8::from(self.dispatcher.pano_active())));
    }

    /// Re-sends the grabs of authorities the cloud holds when no other command of
    /// that domain went out for a keep-alive period; forgets them once another
    /// source (or the arbiter's timeout) took them.
    fn keepalive(&mut self) {
        let period = self.settings.commands.authority_keepalive;
        let snap = self.link.snapshot();
        for (domain, holds, grab) in [
            (
                AuthorityDomain::Flight,
                snap.holds_flight(),
                Command::GrabFlightAuthority,
            ),
            (
                AuthorityDomain::Payload,
                snap.holds_payload(),
                Command::GrabPayloadAuthority,
            ),
        ] {
            if !self.keep.get(domain) {
                continue;
            }
            if !holds {
                self.keep.set(domain, false);
                let holder = snap.authority.map(|a| match domain {
                    AuthorityDomain::Flight => a.flight(),
                    AuthorityDomain::Payload => a.payload(),
                });
                tracing::warn!(?domain, holder = ?holder.flatten(), "the cloud lost its authority (grab again to regain it)");
                continue;
            }
            let due = !period.is_zero() && self.link.idle_for(domain).is_none_or(|d| d >= period);
            if due {
                if let Err(e) = self.link.send(&grab, 0) {
                    tracing::warn!(?domain, error = %e, "authority keep-alive not sent");
                }
            }
        }
    }
}

/// Runs the gateway until `ctx.shutdown`. Marks the service ready once its bus ports
/// and the MQTT task exist (the broker may come later: degraded until then).
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let settings = Arc::new(settings);
    let link = VehicleLink::open(
        &ctx.bus,
        settings.vehicle_id,
        &settings.commands,
        ctx.shutdown.clone(),
    )?;
    let metrics = Metrics::new(&ctx.stats);
    let (emit, mut outgoing) = Emitter::new();
    let (notice_tx, mut notices) = mpsc::unbounded_channel();
    let drc = Drc::new(
        settings.drc.clone(),
        settings.gateway_sn.clone(),
        link.clone(),
        ctx.stats.clone(),
        notice_tx,
        ctx.shutdown.clone(),
    );
    let keep = Arc::new(Keep::default());
    let tasks = TaskClient::open(
        &ctx.bus,
        settings.clone(),
        emit.clone(),
        ctx.shutdown.clone(),
    )?;
    let shared = Shared {
        settings: settings.clone(),
        link: link.clone(),
        emit,
        keep: keep.clone(),
    };
    let sn = &settings.gateway_sn;
    let subscriptions = vec![
        topic(sn, TopicKind::Services),
        topic(sn, TopicKind::EventsReply),
    ];
    // Its own token: stopped after the loop's last drain, so the final replies are
    // handed to the connection before its DISCONNECT.
    let mqtt_stop = tokio_util::sync::CancellationToken::new();
    let _stop_mqtt = mqtt_stop.clone().drop_guard();
    let (client, mut mqtt_events) = mqtt::spawn(&settings.broker, subscriptions, mqtt_stop)?;
    tracing::info!(
        gateway_sn = %settings.gateway_sn,
        broker = %settings.broker.address,
        client_id = %settings.broker.client_id,
        tls = settings.broker.tls_ca_file.is_some(),
        vehicle_id = settings.vehicle_id,
        payload_index = %settings.payload.payload_index,
        "dji-gateway serving the DJI Cloud API (device side)"
    );
    let mut gw = Gateway {
        metrics: metrics.clone(),
        dispatcher: Dispatcher::new(shared, drc, tasks),
        link,
        keep,
        client,
        connected: false,
        outbox: Outbox::new(settings.limits.max_queued_messages),
        limiter: RateLimiter::new(settings.limits.max_messages_per_s),
        warn: WarnLimiter::default(),
        settings,
    };
    metrics.connected.set(0.0);
    ctx.ready();
    ctx.set_state(ServiceState::Degraded);
    let mut ever_connected = false;
    let mut next_tick = Some(Instant::now() + TICK);
    loop {
        let wake = next_tick.unwrap_or_else(|| Instant::now() + IDLE_WAIT);
        tokio::select! {
            _ = ctx.shutdown.cancelled() => break,
            ev = mqtt_events.recv() => match ev {
                None => anyhow::bail!("the MQTT connection task ended"),
                Some(MqttEvent::Connected) => {
                    if ever_connected {
                        metrics.reconnects.inc();
                    }
                    ever_connected = true;
                    gw.connected = true;
                    metrics.connected.set(1.0);
                    ctx.set_state(ServiceState::Running);
                    tracing::info!(broker = %gw.settings.broker.address, queued = gw.outbox.queued(), "connected to the cloud broker");
                    gw.drain();
                }
                Some(MqttEvent::Disconnected { reason, retry_in }) => {
                    metrics.connect_failures.inc();
                    if gw.connected {
                        ctx.set_state(ServiceState::Degraded);
                    } else if let Some(hidden) = gw.warn.allow("broker_unreachable", Instant::now()) {
                        tracing::warn!(broker = %gw.settings.broker.address, error = %reason, retry_in = ?retry_in, similar_since_last_warning = hidden, "cannot reach the cloud broker; retrying");
                    }
                    gw.connected = false;
                    metrics.connected.set(0.0);
                }
                Some(MqttEvent::Message { topic, payload }) => {
                    gw.on_message(&topic, &payload, Instant::now());
                    gw.drain();
                }
            },
            Some(o) = outgoing.recv() => {
                gw.on_outgoing(o, Instant::now());
                gw.drain();
            }
            Some(n) = notices.recv() => {
                gw.on_notice(n, Instant::now());
                gw.drain();
            }
            _ = tokio::time::sleep_until(wake.into()) => gw.tick(Instant::now()),
        }
        gw.update_gauges();
        let now = Instant::now();
        // A tick that was already due stays on its time (the interval it replaces
        // did not move on events either).
        next_tick = match (next_tick, gw.next_tick(now)) {
            (Some(old), Some(new)) if old > now => Some(old.min(new)),
            (_, new) => new,
        };
    }
    // Publish what is still queued (replies to the last requests) while the client
    // can take it; the MQTT task sends a DISCONNECT once it sees the shutdown.
    gw.drain();
    tracing::info!("dji-gateway stopped");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uuids_have_the_v4_layout() {
        let u = uuid();
        let parts: Vec<&str> = u.split('-').collect();
        assert_eq!(
            parts.iter().map(|p| p.len()).collect::<Vec<_>>(),
            [8, 4, 4, 4, 12]
        );
        assert!(parts[2].starts_with('4'));
        assert!(matches!(parts[3].as_bytes()[0], b'8' | b'9' | b'a' | b'b'));
        assert!(u.chars().all(|c| c == '-' || c.is_ascii_hexdigit()));
        assert_ne!(uuid(), u);
    }
}
