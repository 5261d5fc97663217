//! A test "cloud": the other side of the DJI Cloud API, for the end-to-end tests and
//! for trying the gateway by hand. It speaks MQTT (rumqttc) to the same broker as
//! the gateway and plays what a cloud written for the DJI Cloud API does:
//!
//! - [`Cloud`] — the cloud's main connection: subscribes `services_reply` and
//!   `events`; [`Cloud::call`] publishes a `services` request with a fresh `tid`/`bid`
//!   and waits for the `services_reply` carrying that `tid`; every event is kept
//!   ([`Cloud::next_event`]) and an event with `need_reply: 1` is answered on
//!   `events_reply` with `result` 0 at once (unless [`Cloud::set_auto_reply`] turned
//!   that off); [`Cloud::publish_raw`] sends any bytes on any of the gateway's topics
//!   (hostile input).
//! - [`DrcCloud`] — the cloud's end of the DRC link: subscribes `drc/up`, publishes
//!   `drc/down` ([`DrcCloud::send`], [`DrcCloud::drone_control`]), keeps every `drc/up`
//!   message with its arrival time ([`DrcCloud::next_up`], [`DrcCloud::count_up`]) and
//!   can send `heart_beat` in the background ([`DrcCloud::start_heartbeat`]).
//!
//! Both connections survive the broker going away: the event loop keeps polling
//! (rumqttc reconnects on the next poll) and subscribes again after every CONNACK
//! (a clean session forgets subscriptions). Messages published while the broker is
//! down are lost, as they would be for a real cloud with a clean session.
//!
//! Everything is published at QoS 1 (FACTS.md: commands go in at QoS 1).

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{anyhow, bail, Context as _, Result};
use dji_proto::{topic, TopicKind};
use rumqttc::{AsyncClient, Event, EventLoop, MqttOptions, Packet, QoS};
use serde_json::{json, Value};
use tokio::sync::watch;
use tokio::task::JoinHandle;

/// How long [`Cloud::connect`] / [`DrcCloud::connect`] wait for CONNACK + SUBACK.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);
/// How long [`Cloud::call`] waits for the reply, unless changed with
/// [`Cloud::set_reply_timeout`].
pub const DEFAULT_REPLY_TIMEOUT: Duration = Duration::from_secs(10);
/// Largest packet the clients send or accept: room for oversized hostile payloads
/// (the embedded broker's default limit is 1 MiB).
const MAX_PACKET: usize = 1 << 20;
/// Requests queued toward the event loop before `publish` waits.
const CHANNEL_CAP: usize = 256;

/// Milliseconds since the Unix epoch (the `timestamp` of every message).
pub fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// A fresh UUID-shaped identifier (random hex, 8-4-4-4-12) for `tid`/`bid`.
pub fn uuid_like() -> String {
    let h = |n: usize| -> String {
        (0..n)
            .map(|_| char::from_digit(fastrand::u32(0..16), 16).unwrap_or('0'))
            .collect()
    };
    format!("{}-{}-{}-{}-{}", h(8), h(4), h(4), h(4), h(12))
}

/// One message that arrived, with when it arrived.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    pub at: Instant,
    /// The whole JSON message (envelope).
    pub msg: Value,
}

impl Received {
    /// `method` of the message ("" when absent).
    pub fn method(&self) -> &str {
        self.msg["method"].as_str().unwrap_or("")
    }
}

/// Connection bookkeeping shared by both clients.
#[derive(Debug, Default)]
struct Link {
    /// CONNACKs seen (1 after the first connection, +1 per reconnection).
    connacks: u64,
    /// Connected and subscribed since the last CONNACK.
    ready: bool,
    /// The last connection error (for failure messages).
    last_error: Option<String>,
    /// Payloads that were not JSON objects (the gateway should never send one).
    not_json: u64,
}

/// What the main connection received.
#[derive(Debug, Default)]
struct CloudInbox {
    link: Link,
    /// `services_reply` by `tid` (kept until taken).
    replies: HashMap<String, Value>,
    /// `events`, oldest first (kept until taken).
    events: VecDeque<Received>,
    /// `events_reply` answers this client sent.
    event_replies_sent: u64,
}

/// What the DRC connection received.
#[derive(Debug, Default)]
struct DrcInbox {
    link: Link,
    /// `drc/up`, oldest first (kept until taken).
    up: VecDeque<Received>,
}

/// An inbox behind a mutex plus a change counter that wakes waiters.
#[derive(Debug)]
struct Shared<T> {
    inbox: Mutex<T>,
    changed: watch::Sender<u64>,
}

impl<T> Shared<T> {
    fn new(inbox: T) -> Arc<Self> {
        Arc::new(Shared {
            inbox: Mutex::new(inbox),
            changed: watch::channel(0).0,
        })
    }

    fn lock(&self) -> MutexGuard<'_, T> {
        self.inbox.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Runs `f` on the inbox and wakes every waiter.
    fn update<R>(&self, f: impl FnOnce(&mut T) -> R) -> R {
        let r = f(&mut self.lock());
        self.changed.send_modify(|n| *n = n.wrapping_add(1));
        r
    }

    /// Waits until `f` returns `Some` (checked now and after every change).
    async fn wait<R>(
        &self,
        timeout: Duration,
        what: &str,
        mut f: impl FnMut(&mut T) -> Option<R>,
    ) -> Result<R> {
        let mut rx = self.changed.subscribe();
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            rx.mark_unchanged();
            if let Some(r) = f(&mut self.lock()) {
                return Ok(r);
            }
            match tokio::time::timeout_at(deadline, rx.changed()).await {
                Ok(Ok(())) => {}
                Ok(Err(_)) => bail!("{what}: the client's connection task ended"),
                Err(_) => bail!("{what}: not within {timeout:?}"),
            }
        }
    }
}

trait HasLink {
    fn link(&mut self) -> &mut Link;
}

impl HasLink for CloudInbox {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }
}

impl HasLink for DrcInbox {
    fn link(&mut self) -> &mut Link {
        &mut self.link
    }
}

fn options(broker: SocketAddr, client_id: &str) -> MqttOptions {
    let mut o = MqttOptions::new(client_id, broker.ip().to_string(), broker.port());
    o.set_keep_alive(Duration::from_secs(10));
    o.set_max_packet_size(MAX_PACKET, MAX_PACKET);
    o.set_clean_session(true);
    o
}

/// Drives one connection until aborted: subscribes `topics` after every CONNACK,
/// hands every PUBLISH to `on_publish`, keeps polling through errors (reconnect).
fn spawn_driver<T: HasLink + Send + 'static>(
    mut ev: EventLoop,
    client: AsyncClient,
    topics: Vec<String>,
    shared: Arc<Shared<T>>,
    mut on_publish: impl FnMut(&AsyncClient, &mut T, &str, &[u8]) + Send + 'static,
) -> JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            match ev.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    shared.update(|i| {
                        let l = i.link();
                        l.connacks += 1;
                        l.ready = false;
                    });
                    let subs = topics
                        .iter()
                        .map(|t| rumqttc::SubscribeFilter::new(t.clone(), QoS::AtLeastOnce));
                    if let Err(e) = client.try_subscribe_many(subs) {
                        shared.update(|i| i.link().last_error = Some(format!("subscribe: {e}")));
                    }
                }
                Ok(Event::Incoming(Packet::SubAck(_))) => {
                    shared.update(|i| i.link().ready = true);
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    shared.update(|i| on_publish(&client, i, &p.topic, &p.payload));
                }
                Ok(_) => {}
                Err(e) => {
                    shared.update(|i| {
                        let l = i.link();
                        l.ready = false;
                        l.last_error = Some(e.to_string());
                    });
                    // The next poll reconnects; do not spin while the broker is away.
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
        }
    })
}

/// Parses a received payload as a JSON object, counting what is not one.
fn json_object(link: &mut Link, payload: &[u8]) -> Option<Value> {
    match serde_json::from_slice::<Value>(payload) {
        Ok(v) if v.is_object() => Some(v),
        _ => {
            link.not_json += 1;
            None
        }
    }
}

/// The cloud's main connection (services and events) to one gateway.
#[derive(Debug)]
pub struct Cloud {
    client: AsyncClient,
    gateway_sn: String,
    shared: Arc<Shared<CloudInbox>>,
    auto_reply: Arc<AtomicBool>,
    reply_timeout: Duration,
    task: JoinHandle<()>,
}

impl Cloud {
    /// Connects to the broker at `broker` as a cloud of gateway `gateway_sn`, and
    /// returns once subscribed to its `services_reply` and `events`. Retries while the
    /// broker is not listening yet, up to [`CONNECT_TIMEOUT`]. Call inside a tokio
    /// runtime (the connection is driven by a spawned task).
    pub async fn connect(broker: SocketAddr, gateway_sn: &str) -> Result<Cloud> {
        let id = format!("e2e-cloud-{}-{:08x}", gateway_sn, fastrand::u32(..));
        let (client, ev) = AsyncClient::new(options(broker, &id), CHANNEL_CAP);
        let shared = Shared::new(CloudInbox::default());
        let auto_reply = Arc::new(AtomicBool::new(true));
        let replies_topic = topic(gateway_sn, TopicKind::ServicesReply);
        let events_topic = topic(gateway_sn, TopicKind::Events);
        let events_reply_topic = topic(gateway_sn, TopicKind::EventsReply);
        let task = spawn_driver(
            ev,
            client.clone(),
            vec![replies_topic.clone(), events_topic.clone()],
            shared.clone(),
            {
                let auto_reply = auto_reply.clone();
                move |client, inbox: &mut CloudInbox, t, payload| {
                    let Some(msg) = json_object(&mut inbox.link, payload) else {
                        return;
                    };
                    if t == replies_topic {
                        let tid = msg["tid"].as_str().unwrap_or("").to_string();
                        inbox.replies.insert(tid, msg);
                    } else if t == events_topic {
                        if msg["need_reply"].as_i64() == Some(1)
                            && auto_reply.load(Ordering::Relaxed)
                        {
                            let reply = json!({
                                "tid": msg["tid"],
                                "bid": msg["bid"],
                                "timestamp": now_ms(),
                                "method": msg["method"],
                                "data": { "result": 0 },
                            });
                            if client
                                .try_publish(
                                    events_reply_topic.as_str(),
                                    QoS::AtLeastOnce,
                                    false,
                                    reply.to_string(),
                                )
                                .is_ok()
                            {
                                inbox.event_replies_sent += 1;
                            }
                        }
                        inbox.events.push_back(Received {
                            at: Instant::now(),
                            msg,
                        });
                    }
                }
            },
        );
        let cloud = Cloud {
            client,
            gateway_sn: gateway_sn.to_string(),
            shared,
            auto_reply,
            reply_timeout: DEFAULT_REPLY_TIMEOUT,
            task,
        };
        cloud.wait_ready(CONNECT_TIMEOUT).await?;
        Ok(cloud)
    }

    /// The gateway serial number this cloud talks to.
    pub fn gateway_sn(&self) -> &str {
        &self.gateway_sn
    }

    /// How long [`Cloud::call`] waits for a reply.
    pub fn set_reply_timeout(&mut self, timeout: Duration) {
        self.reply_timeout = timeout;
    }

    /// Whether events with `need_reply: 1` are answered automatically (default on).
    pub fn set_auto_reply(&self, on: bool) {
        self.auto_reply.store(on, Ordering::Relaxed);
    }

    /// `events_reply` answers sent so far.
    pub fn event_replies_sent(&self) -> u64 {
        self.shared.lock().event_replies_sent
    }

    /// CONNACKs so far: 1 after connecting, +1 for each reconnection.
    pub fn connections(&self) -> u64 {
        self.shared.lock().link.connacks
    }

    /// Waits until connected and subscribed (again, after a broker outage).
    pub async fn wait_ready(&self, timeout: Duration) -> Result<()> {
        let sn = self.gateway_sn.clone();
        self.shared
            .wait(
                timeout,
                &format!("cloud of {sn}: connected and subscribed"),
                |i| i.link.ready.then_some(()),
            )
            .await
            .with_context(|| format!("last error: {:?}", self.shared.lock().link.last_error))
    }

    /// Waits until the connection has been established more than `n` times (a
    /// reconnection after `n` connections) and subscribed again.
    pub async fn wait_reconnected(&self, n: u64, timeout: Duration) -> Result<()> {
        self.shared
            .wait(timeout, "cloud reconnected", |i| {
                (i.link.connacks > n && i.link.ready).then_some(())
            })
            .await
    }

    /// Publishes a `services` request `method` with `data` (fresh `tid` and `bid`) and
    /// returns its `tid` without waiting.
    pub async fn send(&self, method: &str, data: Value) -> Result<String> {
        let tid = uuid_like();
        let msg = json!({
            "tid": tid,
            "bid": uuid_like(),
            "timestamp": now_ms(),
            "method": method,
            "data": data,
        });
        self.publish_raw(TopicKind::Services, msg.to_string().into_bytes())
            .await?;
        Ok(tid)
    }

    /// Calls service `method` with `data`: publishes the request and returns the
    /// whole `services_reply` envelope (`data.result` is the outcome), or an error
    /// when no reply arrives within the reply timeout.
    pub async fn call(&self, method: &str, data: Value) -> Result<Value> {
        let tid = self.send(method, data).await?;
        self.reply(&tid, self.reply_timeout)
            .await
            .with_context(|| format!("calling {method}"))
    }

    /// Calls `method` and returns `data.result` of the reply (an error when the reply
    /// has no integer `data.result`).
    pub async fn call_result(&self, method: &str, data: Value) -> Result<i64> {
        let reply = self.call(method, data).await?;
        reply["data"]["result"]
            .as_i64()
            .ok_or_else(|| anyhow!("{method}: reply without data.result: {reply}"))
    }

    /// Waits for (and takes) the `services_reply` with this `tid`.
    pub async fn reply(&self, tid: &str, timeout: Duration) -> Result<Value> {
        self.shared
            .wait(timeout, &format!("services_reply tid {tid}"), |i| {
                i.replies.remove(tid)
            })
            .await
    }

    /// Publishes `payload` as is on the gateway's topic `kind` (hostile input).
    pub async fn publish_raw(&self, kind: TopicKind, payload: Vec<u8>) -> Result<()> {
        self.client
            .publish(
                topic(&self.gateway_sn, kind),
                QoS::AtLeastOnce,
                false,
                payload,
            )
            .await
            .map_err(|e| anyhow!("publish: {e}"))
    }

    /// Answers `event` (a whole `events` message) on `events_reply` with `result`, as
    /// the automatic reply does; for tests that answer by hand
    /// ([`Cloud::set_auto_reply`] off).
    pub async fn reply_event(&self, event: &Value, result: i64) -> Result<()> {
        let reply = json!({
            "tid": event["tid"],
            "bid": event["bid"],
            "timestamp": now_ms(),
            "method": event["method"],
            "data": { "result": result },
        });
        self.publish_raw(TopicKind::EventsReply, reply.to_string().into_bytes())
            .await
    }

    /// Waits for (and takes) the oldest event `method` not taken yet.
    pub async fn next_event(&self, method: &str, timeout: Duration) -> Result<Received> {
        self.next_event_where(method, timeout, |_| true).await
    }

    /// Waits for (and takes) the oldest event `method` whose `data` satisfies `pred`;
    /// other events stay.
    pub async fn next_event_where(
        &self,
        method: &str,
        timeout: Duration,
        mut pred: impl FnMut(&Value) -> bool,
    ) -> Result<Received> {
        self.shared
            .wait(timeout, &format!("event {method}"), |i| {
                take_first(&mut i.events, method, &mut pred)
            })
            .await
    }

    /// Takes every event `method` received so far, oldest first.
    pub fn take_events(&self, method: &str) -> Vec<Received> {
        take_all(&mut self.shared.lock().events, method)
    }

    /// Received payloads that were not JSON objects.
    pub fn not_json(&self) -> u64 {
        self.shared.lock().link.not_json
    }
}

impl Drop for Cloud {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// The cloud's end of the DRC link of one gateway, on the broker `drc_mode_enter`
/// names.
#[derive(Debug)]
pub struct DrcCloud {
    client: AsyncClient,
    gateway_sn: String,
    shared: Arc<Shared<DrcInbox>>,
    heartbeat_seq: Arc<AtomicI64>,
    heartbeats_sent: Arc<AtomicU64>,
    heartbeat: Mutex<Option<JoinHandle<()>>>,
    task: JoinHandle<()>,
}

impl DrcCloud {
    /// Connects to `broker` and returns once subscribed to `drc/up` of `gateway_sn`.
    pub async fn connect(broker: SocketAddr, gateway_sn: &str) -> Result<DrcCloud> {
        let id = format!("e2e-drc-cloud-{}-{:08x}", gateway_sn, fastrand::u32(..));
        let (client, ev) = AsyncClient::new(options(broker, &id), CHANNEL_CAP);
        let shared = Shared::new(DrcInbox::default());
        let up_topic = topic(gateway_sn, TopicKind::DrcUp);
        let task = spawn_driver(
            ev,
            client.clone(),
            vec![up_topic],
            shared.clone(),
            |_, inbox: &mut DrcInbox, _, payload| {
                if let Some(msg) = json_object(&mut inbox.link, payload) {
                    inbox.up.push_back(Received {
                        at: Instant::now(),
                        msg,
                    });
                }
            },
        );
        let drc = DrcCloud {
            client,
            gateway_sn: gateway_sn.to_string(),
            shared,
            heartbeat_seq: Arc::new(AtomicI64::new(0)),
            heartbeats_sent: Arc::new(AtomicU64::new(0)),
            heartbeat: Mutex::new(None),
            task,
        };
        drc.shared
            .wait(CONNECT_TIMEOUT, "DRC cloud connected and subscribed", |i| {
                i.link.ready.then_some(())
            })
            .await
            .with_context(|| format!("last error: {:?}", drc.shared.lock().link.last_error))?;
        Ok(drc)
    }

    /// Publishes `{"method": method, "data": data}` on `drc/down`.
    pub async fn send(&self, method: &str, data: Value) -> Result<()> {
        let msg = json!({ "method": method, "data": data });
        self.publish_raw(msg.to_string().into_bytes()).await
    }

    /// Publishes `payload` as is on `drc/down` (hostile input).
    pub async fn publish_raw(&self, payload: Vec<u8>) -> Result<()> {
        self.client
            .publish(
                topic(&self.gateway_sn, TopicKind::DrcDown),
                QoS::AtLeastOnce,
                false,
                payload,
            )
            .await
            .map_err(|e| anyhow!("publish: {e}"))
    }

    /// Sends one `drone_control` (sticks: `x` left, `y` forward, `h` up in m/s, `w`
    /// clockwise in deg/s) and returns the reply's `data`. Replies come back in order
    /// on one connection: the oldest `drone_control` reply not taken yet is this one's
    /// when every earlier one was taken.
    pub async fn drone_control(
        &self,
        seq: i64,
        x: f64,
        y: f64,
        h: f64,
        w: f64,
        timeout: Duration,
    ) -> Result<Value> {
        self.send(
            "drone_control",
            json!({ "seq": seq, "x": x, "y": y, "h": h, "w": w }),
        )
        .await?;
        Ok(self.next_up("drone_control", timeout).await?.msg["data"].clone())
    }

    /// Waits for (and takes) the oldest `drc/up` message `method` not taken yet.
    pub async fn next_up(&self, method: &str, timeout: Duration) -> Result<Received> {
        self.next_up_where(method, timeout, |_| true).await
    }

    /// Waits for (and takes) the oldest `drc/up` message `method` whose `data`
    /// satisfies `pred`; others stay.
    pub async fn next_up_where(
        &self,
        method: &str,
        timeout: Duration,
        mut pred: impl FnMut(&Value) -> bool,
    ) -> Result<Received> {
        self.shared
            .wait(timeout, &format!("drc/up {method}"), |i| {
                take_first(&mut i.up, method, &mut pred)
            })
            .await
    }

    /// Takes every `drc/up` message `method` received so far, oldest first.
    pub fn take_up(&self, method: &str) -> Vec<Received> {
        take_all(&mut self.shared.lock().up, method)
    }

    /// How many `drc/up` messages `method` (taken or not: counts what is still kept)
    /// arrived within `from..to`.
    pub fn count_up(&self, method: &str, from: Instant, to: Instant) -> usize {
        self.shared
            .lock()
            .up
            .iter()
            .filter(|m| m.method() == method && m.at >= from && m.at < to)
            .count()
    }

    /// The newest `drc/up` message `method` kept (not taken).
    pub fn latest_up(&self, method: &str) -> Option<Received> {
        self.shared
            .lock()
            .up
            .iter()
            .rev()
            .find(|m| m.method() == method)
            .cloned()
    }

    /// Sends `heart_beat` every `period` in the background (seq counting up,
    /// timestamp now) until [`DrcCloud::stop_heartbeat`] or drop.
    pub fn start_heartbeat(&self, period: Duration) {
        let client = self.client.clone();
        let down = topic(&self.gateway_sn, TopicKind::DrcDown);
        let seq = self.heartbeat_seq.clone();
        let sent = self.heartbeats_sent.clone();
        let task = tokio::spawn(async move {
            let mut tick = tokio::time::interval(period);
            loop {
                tick.tick().await;
                let msg = json!({
                    "method": "heart_beat",
                    "data": { "seq": seq.fetch_add(1, Ordering::Relaxed), "timestamp": now_ms() },
                });
                if client
                    .publish(down.as_str(), QoS::AtLeastOnce, false, msg.to_string())
                    .await
                    .is_ok()
                {
                    sent.fetch_add(1, Ordering::Relaxed);
                }
            }
        });
        if let Some(old) = self.lock_heartbeat().replace(task) {
            old.abort();
        }
    }

    /// Stops the background heartbeat.
    pub fn stop_heartbeat(&self) {
        if let Some(task) = self.lock_heartbeat().take() {
            task.abort();
        }
    }

    /// Heartbeats the background task has published.
    pub fn heartbeats_sent(&self) -> u64 {
        self.heartbeats_sent.load(Ordering::Relaxed)
    }

    /// Received payloads that were not JSON objects.
    pub fn not_json(&self) -> u64 {
        self.shared.lock().link.not_json
    }

    fn lock_heartbeat(&self) -> MutexGuard<'_, Option<JoinHandle<()>>> {
        self.heartbeat.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Drop for DrcCloud {
    fn drop(&mut self) {
        self.stop_heartbeat();
        self.task.abort();
    }
}

/// Removes and returns the oldest message `method` whose `data` satisfies `pred`.
fn take_first(
    queue: &mut VecDeque<Received>,
    method: &str,
    pred: &mut impl FnMut(&Value) -> bool,
) -> Option<Received> {
    let at = queue
        .iter()
        .position(|m| m.method() == method && pred(&m.msg["data"]))?;
    queue.remove(at)
}

/// Removes and returns every message `method`, oldest first.
fn take_all(queue: &mut VecDeque<Received>, method: &str) -> Vec<Received> {
    let (taken, kept): (Vec<_>, Vec<_>) = std::mem::take(queue)
        .into_iter()
        .partition(|m| m.method() == method);
    *queue = kept.into();
    taken
}
