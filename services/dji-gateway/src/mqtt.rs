//! The connection to the cloud's broker: one task owns the rumqttc `EventLoop`,
//! connects (credentials, TLS), subscribes `services` and `events_reply` (QoS 1) on
//! every (re)connect, forwards what arrives, and when the broker goes away waits a
//! jittered, doubling [`Backoff`] ([`RECONNECT_JITTER`]) and connects again. The gateway's state lives
//! elsewhere and is untouched by reconnects.
//!
//! QoS: we subscribe at 1 and publish replies and events at 1. FACTS.md notes the
//! reference replies at QoS 2; the document names none, and QoS 1 is what a cloud
//! SDK and every broker handle alike. Duplicates are harmless: replies carry the
//! request's tid/bid and events their own, so a cloud de-duplicates by them.

use std::time::Duration;

use rumqttc::{AsyncClient, ConnectReturnCode, Event, EventLoop, MqttOptions, Packet, QoS};
use skymesh_runtime::{Backoff, CancellationToken};
use tokio::sync::mpsc;

use crate::config::BrokerSettings;

/// Requests the client queues towards the event loop.
const CLIENT_CAPACITY: usize = 64;
/// Relative jitter of the broker links' reconnect delays (cloud and DRC): each delay
/// is drawn from ±50 % of the doubled delay (never above the configured maximum), so
/// gateways that lost the same broker do not come back in lockstep. The shortest
/// delay is half the doubled one, as with the equal jitter used before.
pub const RECONNECT_JITTER: f64 = 0.5;
/// Largest packet accepted from the broker: far above any message we accept, so an
/// oversized one reaches us to be counted and dropped instead of killing the link.
const MAX_INCOMING_PACKET: usize = 4 * 1024 * 1024;
const MAX_OUTGOING_PACKET: usize = 1024 * 1024;
/// How long a connection attempt may take (TCP, TLS, CONNACK), seconds.
const CONNECT_TIMEOUT_S: u64 = 5;

/// What the connection task reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MqttEvent {
    /// Connected (CONNACK accepted) and the subscriptions were sent.
    Connected,
    /// The connection failed or broke; `retry_in` until the next attempt.
    Disconnected { reason: String, retry_in: Duration },
    /// A PUBLISH arrived.
    Message { topic: String, payload: Vec<u8> },
}

/// The client options for `b`.
pub fn options(b: &BrokerSettings) -> anyhow::Result<MqttOptions> {
    let mut o = MqttOptions::new(b.client_id.clone(), b.host.clone(), b.port);
    o.set_keep_alive(b.keep_alive)
        .set_clean_session(true)
        .set_max_packet_size(MAX_INCOMING_PACKET, MAX_OUTGOING_PACKET);
    if !b.username.is_empty() {
        o.set_credentials(b.username.clone(), b.password.clone());
    }
    if let Some(ca) = &b.tls_ca_file {
        o.set_transport(crate::tls::transport(ca)?);
    }
    Ok(o)
}

/// Starts the connection task; it ends with `shutdown` (after a DISCONNECT).
pub fn spawn(
    b: &BrokerSettings,
    subscriptions: Vec<String>,
    shutdown: CancellationToken,
) -> anyhow::Result<(AsyncClient, mpsc::Receiver<MqttEvent>)> {
    let (client, mut eventloop) = AsyncClient::new(options(b)?, CLIENT_CAPACITY);
    let mut net = rumqttc::NetworkOptions::new();
    // Small request/reply messages: no Nagle delay (with the peer's delayed ACK it
    // adds ~40 ms to a reply that follows a publish).
    net.set_tcp_nodelay(true);
    net.set_connection_timeout(CONNECT_TIMEOUT_S);
    eventloop.set_network_options(net);
    let (tx, rx) = mpsc::channel(1024);
    let backoff = Backoff::new(b.reconnect_initial, b.reconnect_max).with_jitter(RECONNECT_JITTER);
    let task_client = client.clone();
    tokio::spawn(
        async move { run(task_client, eventloop, subscriptions, backoff, tx, shutdown).await },
    );
    Ok((client, rx))
}

async fn run(
    client: AsyncClient,
    mut eventloop: EventLoop,
    subscriptions: Vec<String>,
    mut backoff: Backoff,
    tx: mpsc::Sender<MqttEvent>,
    shutdown: CancellationToken,
) {
    let mut connected = false;
    loop {
        let polled = tokio::select! {
            _ = shutdown.cancelled() => break,
            r = eventloop.poll() => r,
        };
        match polled {
            Ok(Event::Incoming(Packet::ConnAck(ack))) => {
                if ack.code != ConnectReturnCode::Success {
                    // rumqttc reports refusals as errors; handled below.
                    continue;
                }
                backoff.reset();
                connected = true;
                for t in &subscriptions {
                    if let Err(e) = client.try_subscribe(t.clone(), QoS::AtLeastOnce) {
                        tracing::error!(topic = %t, error = %e, "cannot queue a subscription");
                    }
                }
                if tx.send(MqttEvent::Connected).await.is_err() {
                    break;
                }
            }
            Ok(Event::Incoming(Packet::SubAck(ack))) => {
                for code in &ack.return_codes {
                    if matches!(code, rumqttc::SubscribeReasonCode::Failure) {
                        tracing::error!(pkid = ack.pkid, "the broker refused a subscription");
                    }
                }
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let m = MqttEvent::Message {
                    topic: p.topic,
                    payload: p.payload.to_vec(),
                };
                if tx.send(m).await.is_err() {
                    break;
                }
            }
            Ok(_) => {}
            Err(e) => {
                let retry_in = backoff.next_delay(fastrand::f64());
                let reason = e.to_string();
                if connected {
                    tracing::warn!(error = %reason, retry_in = ?retry_in, "lost the cloud broker");
                } else {
                    tracing::debug!(error = %reason, retry_in = ?retry_in, "cannot reach the cloud broker");
                }
                connected = false;
                if tx
                    .send(MqttEvent::Disconnected { reason, retry_in })
                    .await
                    .is_err()
                {
                    break;
                }
                tokio::select! {
                    _ = shutdown.cancelled() => break,
                    _ = tokio::time::sleep(retry_in) => {}
                }
            }
        }
    }
    if connected {
        // Best effort: tell the broker we leave (no last will is configured).
        let _ = client.try_disconnect();
        let _ = tokio::time::timeout(Duration::from_millis(500), async {
            while let Ok(ev) = eventloop.poll().await {
                if matches!(ev, Event::Outgoing(rumqttc::Outgoing::Disconnect)) {
                    break;
                }
            }
        })
        .await;
    }
}
