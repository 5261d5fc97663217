//! The gate: every client connection (plain or, after TLS, from the terminator)
//! goes through here before rumqttd, which only listens on an internal loopback
//! port.
//!
//! rumqttd 0.20 checks a username/password at CONNECT but has no topic ACLs and no
//! limit on the topics it learns (a log per subscribed filter, an entry per
//! published topic, kept until it restarts). So the gate reads the MQTT 3.1.1
//! packets a client sends (rumqttd's own codec, `rumqttd::protocol::v4`), and:
//! - CONNECT: checks the login itself (constant time); refused logins get CONNACK
//!   4/5 and never reach rumqttd. It forwards the CONNECT with the password
//!   replaced by a secret made at start, which is the only password rumqttd
//!   accepts: a local process that finds the internal port cannot bypass the ACLs.
//! - PUBLISH (and the CONNECT's will): the topic must match one of the user's
//!   `publish` filters; SUBSCRIBE: each filter must lie within one of the user's
//!   `subscribe` filters. A denied packet is not forwarded and the connection is
//!   closed (MQTT 3.1.1 has no negative PUBACK), counted in
//!   `skymesh_mqtt_refused_total{reason}` and logged (rate-limited).
//! - Topic names and filters are counted in one set, at most `max_topics`
//!   (`skymesh_mqtt_topics`): a PUBLISH or SUBSCRIBE that would add one more is
//!   refused the same way (`reason="topic_limit"`). Like rumqttd's own tables the
//!   set only grows until the broker restarts.
//! - DISCONNECT without a will: the gate ends the upstream connection with a plain
//!   close instead of forwarding the packet. rumqttd 0.20 handles a DISCONNECT
//!   packet and then the closed socket as two disconnections and logs the second
//!   at ERROR (`no-connection id N is already gone`, or `router-drop` when the
//!   socket side loses the race): a correct client stop must not log an error.
//!   Without a will both end the session the same way in rumqttd (the socket close
//!   only additionally fires the will, and there is none). A client with a will
//!   still has its DISCONNECT forwarded (it must discard the will); rumqttd may then
//!   log that ERROR line.
//!
//! Everything rumqttd sends is copied to the client unchanged.

use std::collections::{BTreeMap, HashSet};
use std::net::SocketAddr;
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use bytes::BytesMut;
use rumqttd::protocol::v4::{self, V4};
use rumqttd::protocol::{ConnAck, ConnectReturnCode, Error as ProtoError, Login, Packet, Protocol};
use skymesh_runtime::{CounterFamily, Gauge, Stats, WarnLimiter};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::acl;
use crate::config::User;

/// Why a client was refused (label `reason` of `skymesh_mqtt_refused_total`).
pub mod reason {
    /// Missing, unknown or wrong credentials (CONNACK 4).
    pub const LOGIN: &str = "login";
    /// A PUBLISH, or a CONNECT's will (CONNACK 5), outside the user's `publish`
    /// filters.
    pub const PUBLISH_ACL: &str = "publish_acl";
    /// A SUBSCRIBE filter outside the user's `subscribe` filters.
    pub const SUBSCRIBE_ACL: &str = "subscribe_acl";
    /// A new topic or filter beyond `max_topics`.
    pub const TOPIC_LIMIT: &str = "topic_limit";
    /// Not MQTT 3.1.1, a malformed or oversized packet, or no CONNECT in time.
    pub const PROTOCOL: &str = "protocol";
    /// rumqttd's internal listener could not be reached.
    pub const UPSTREAM: &str = "upstream";
    pub const ALL: [&str; 6] = [
        LOGIN,
        PUBLISH_ACL,
        SUBSCRIBE_ACL,
        TOPIC_LIMIT,
        PROTOCOL,
        UPSTREAM,
    ];
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// How long the gate lets rumqttd close a connection it ended (so rumqttd reads a
/// clean end of stream rather than a reset).
const DRAIN: Duration = Duration::from_secs(2);

/// The gate's series.
#[derive(Debug, Clone)]
pub struct GateMetrics {
    /// `skymesh_mqtt_refused_total{reason}` (see [`reason`]).
    refused: CounterFamily,
    /// `skymesh_mqtt_topics`: topic names and filters known (at most `max_topics`).
    topics: Gauge,
}

impl GateMetrics {
    pub fn new(stats: &Stats) -> Self {
        let refused = CounterFamily::new(stats, "skymesh_mqtt_refused_total", ("reason", None));
        for r in reason::ALL {
            refused.add(r, 0);
        }
        GateMetrics {
            refused,
            topics: stats.gauge("skymesh_mqtt_topics", &[]),
        }
    }
}

/// What the gate enforces, shared by every connection.
pub struct Gate {
    /// username → password and ACL; empty = anonymous clients, no ACL.
    users: BTreeMap<String, User>,
    /// The only password rumqttd accepts.
    secret: String,
    /// rumqttd's internal listener.
    upstream: SocketAddr,
    max_packet: usize,
    connect_timeout: Duration,
    max_topics: usize,
    topics: Mutex<HashSet<String>>,
    metrics: GateMetrics,
    warnings: Mutex<WarnLimiter<(std::net::IpAddr, &'static str)>>,
}

impl std::fmt::Debug for Gate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gate")
            .field("users", &self.users.keys().collect::<Vec<_>>())
            .field("upstream", &self.upstream)
            .field("max_topics", &self.max_topics)
            .finish_non_exhaustive()
    }
}

/// How one client connection ended (for the log).
#[derive(Debug)]
enum End {
    /// The client closed or sent DISCONNECT.
    Client,
    /// rumqttd closed the connection.
    Broker,
    Refused(&'static str, String),
}

impl Gate {
    pub fn new(
        settings: &crate::Settings,
        secret: String,
        upstream: SocketAddr,
        metrics: GateMetrics,
    ) -> Gate {
        Gate {
            users: settings.users.clone(),
            secret,
            upstream,
            max_packet: settings.max_payload_size,
            connect_timeout: settings.connection_timeout,
            max_topics: settings.max_topics,
            topics: Mutex::default(),
            metrics,
            warnings: Mutex::default(),
        }
    }

    /// The secret rumqttd's authentication compares against.
    pub fn secret(&self) -> &str {
        &self.secret
    }

    /// Counts `topic` (a name or a filter) among the broker's topics; false if it is
    /// new and `max_topics` are known already.
    fn admit_topic(&self, topic: &str) -> bool {
        let mut known = lock(&self.topics);
        if known.contains(topic) {
            return true;
        }
        if known.len() >= self.max_topics {
            return false;
        }
        known.insert(topic.to_owned());
        self.metrics.topics.set(known.len() as f64);
        true
    }

    fn refuse(&self, peer: SocketAddr, client: &str, why: &'static str, detail: &str) {
        self.metrics.refused.inc(why);
        let allowed = lock(&self.warnings).allow((peer.ip(), why), Instant::now());
        match allowed {
            Some(hidden) => tracing::warn!(
                %peer,
                client,
                reason = why,
                detail,
                similar_since_last_warning = hidden,
                "MQTT client refused"
            ),
            None => tracing::debug!(%peer, client, reason = why, detail, "MQTT client refused"),
        }
    }

    /// Serves one client connection until it or rumqttd ends it.
    pub async fn client<S>(&self, stream: S, peer: SocketAddr)
    where
        S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    {
        let (mut cr, mut cw) = tokio::io::split(stream);
        let mut buf = BytesMut::with_capacity(4096);
        let first = tokio::time::timeout(
            self.connect_timeout,
            read_frame(&mut cr, &mut buf, self.max_packet),
        )
        .await;
        let frame = match first {
            Err(_) => {
                return self.refuse(peer, "", reason::PROTOCOL, "no CONNECT in time");
            }
            Ok(Ok(Some(f))) => f,
            Ok(Ok(None)) => return,
            Ok(Err(e)) => return self.refuse(peer, "", reason::PROTOCOL, &e),
        };
        let (connect, will, login) = match V4.read_mut(&mut frame.clone(), self.max_packet) {
            Ok(Packet::Connect(c, _, will, _, login)) => (c, will, login),
            Ok(other) => {
                let detail = format!("first packet is not CONNECT: {other:?}");
                return self.refuse(peer, "", reason::PROTOCOL, &detail);
            }
            Err(e) => {
                let detail = format!("not an MQTT 3.1.1 CONNECT: {e}");
                return self.refuse(peer, "", reason::PROTOCOL, &detail);
            }
        };
        let client_id = connect.client_id.clone();
        // Who is this? `None` = anonymous (no users configured).
        let user = match self.login(login.as_ref()) {
            Ok(u) => u,
            Err(()) => {
                self.refuse(
                    peer,
                    &client_id,
                    reason::LOGIN,
                    "bad or missing credentials",
                );
                connack(&mut cw, ConnectReturnCode::BadUserNamePassword).await;
                return;
            }
        };
        let username = login
            .as_ref()
            .map(|l| l.username.clone())
            .unwrap_or_default();
        let user_acl = user.map(|u| &self.users[u]);
        if let Some(w) = &will {
            let topic = String::from_utf8_lossy(&w.topic).into_owned();
            let denied = if acl::valid_topic(&topic).is_err() {
                Some(reason::PROTOCOL)
            } else if user_acl.is_some_and(|u| !acl::any_matches(&u.publish, &topic)) {
                Some(reason::PUBLISH_ACL)
            } else if !self.admit_topic(&topic) {
                Some(reason::TOPIC_LIMIT)
            } else {
                None
            };
            if let Some(why) = denied {
                self.refuse(peer, &client_id, why, &format!("will topic `{topic}`"));
                connack(&mut cw, ConnectReturnCode::NotAuthorized).await;
                return;
            }
        }
        let has_will = will.is_some();
        let up = match TcpStream::connect(self.upstream).await {
            Ok(s) => s,
            Err(e) => {
                let detail = format!("cannot reach the broker on {}: {e}", self.upstream);
                self.refuse(peer, &client_id, reason::UPSTREAM, &detail);
                connack(&mut cw, ConnectReturnCode::ServiceUnavailable).await;
                return;
            }
        };
        let _ = up.set_nodelay(true);
        let (mut ur, mut uw) = up.into_split();
        // The CONNECT as sent, but with the internal secret as the password and,
        // with logins, the client id in the user's own namespace.
        let login = Login {
            username: username.clone(),
            password: self.secret.clone(),
        };
        let mut connect = connect;
        if user.is_some() {
            connect.client_id = namespaced(&username, &connect.client_id);
        }
        let mut out = BytesMut::new();
        if V4
            .write(
                Packet::Connect(connect, None, will, None, Some(login)),
                &mut out,
            )
            .is_err()
            || uw.write_all(&out).await.is_err()
        {
            return;
        }
        // rumqttd → client, unchanged. When the client stops reading, keep reading
        // rumqttd's side so it sees our close as a clean end of stream.
        let mut down = tokio::spawn(async move {
            let _ = tokio::io::copy(&mut ur, &mut cw).await;
            let _ = cw.shutdown().await;
            let _ = tokio::io::copy(&mut ur, &mut tokio::io::sink()).await;
        });
        let end = tokio::select! {
            end = self.pump(&mut cr, &mut uw, buf, user_acl, has_will) => end,
            _ = &mut down => End::Broker,
        };
        match &end {
            End::Refused(why, detail) => self.refuse(peer, &client_id, why, detail),
            End::Client | End::Broker => {
                tracing::debug!(%peer, client = %client_id, user = %username, end = ?end, "MQTT client gone")
            }
        }
        if !matches!(end, End::Broker) {
            // A FIN, not a reset: rumqttd then closes its side, ending `down`.
            let _ = uw.shutdown().await;
            drop(uw);
            if tokio::time::timeout(DRAIN, &mut down).await.is_err() {
                down.abort();
            }
        }
    }

    /// The user named by `login`, `Ok(None)` for anonymous clients (no users
    /// configured; credentials are then ignored), `Err` if refused.
    fn login(&self, login: Option<&Login>) -> Result<Option<&str>, ()> {
        if self.users.is_empty() {
            return Ok(None);
        }
        let login = login.ok_or(())?;
        let (name, user) = self.users.get_key_value(&login.username).ok_or(())?;
        if constant_time_eq(user.password.as_bytes(), login.password.as_bytes()) {
            Ok(Some(name))
        } else {
            Err(())
        }
    }

    /// Client → rumqttd: checks each packet, forwards the allowed ones as received.
    async fn pump<R, W>(
        &self,
        cr: &mut R,
        uw: &mut W,
        mut buf: BytesMut,
        user: Option<&User>,
        has_will: bool,
    ) -> End
    where
        R: AsyncRead + Unpin,
        W: AsyncWrite + Unpin,
    {
        loop {
            let frame = match read_frame(cr, &mut buf, self.max_packet).await {
                Ok(Some(f)) => f,
                Ok(None) => return End::Client,
                Err(e) => return End::Refused(reason::PROTOCOL, e),
            };
            match V4.read_mut(&mut frame.clone(), self.max_packet) {
                Ok(Packet::Publish(p, _)) => {
                    let Ok(topic) = std::str::from_utf8(&p.topic) else {
                        return End::Refused(reason::PROTOCOL, "topic is not UTF-8".into());
                    };
                    if acl::valid_topic(topic).is_err() {
                        let detail = format!("publish to `{topic}`: not a topic name");
                        return End::Refused(reason::PROTOCOL, detail);
                    }
                    if user.is_some_and(|u| !acl::any_matches(&u.publish, topic)) {
                        let detail = format!("publish to `{topic}`");
                        return End::Refused(reason::PUBLISH_ACL, detail);
                    }
                    if !self.admit_topic(topic) {
                        let detail = format!("publish to `{topic}`: {} known", self.max_topics);
                        return End::Refused(reason::TOPIC_LIMIT, detail);
                    }
                }
                Ok(Packet::Subscribe(s, _)) => {
                    for f in &s.filters {
                        // rumqttd's shared subscriptions: the ACL applies to the filter.
                        let path = shared_filter(&f.path);
                        if acl::valid_filter(path).is_err() {
                            let detail = format!("subscribe to `{}`: not a filter", f.path);
                            return End::Refused(reason::PROTOCOL, detail);
                        }
                        if user.is_some_and(|u| !acl::any_covers(&u.subscribe, path)) {
                            let detail = format!("subscribe to `{}`", f.path);
                            return End::Refused(reason::SUBSCRIBE_ACL, detail);
                        }
                        if !self.admit_topic(&f.path) {
                            let detail =
                                format!("subscribe to `{}`: {} known", f.path, self.max_topics);
                            return End::Refused(reason::TOPIC_LIMIT, detail);
                        }
                    }
                }
                // Without a will, a plain close ends the session the same way in
                // rumqttd and logs no error (see the module documentation).
                Ok(Packet::Disconnect(..)) if !has_will => return End::Client,
                Ok(Packet::Disconnect(..)) => {
                    let _ = uw.write_all(&frame).await;
                    return End::Client;
                }
                Ok(Packet::Connect(..)) => {
                    return End::Refused(reason::PROTOCOL, "a second CONNECT".into());
                }
                Ok(_) => {}
                Err(e) => return End::Refused(reason::PROTOCOL, format!("malformed packet: {e}")),
            }
            if uw.write_all(&frame).await.is_err() {
                return End::Broker;
            }
        }
    }
}

/// rumqttd keys sessions (persistent subscriptions, the one connection per id) by
/// client id alone: with logins, another user must neither take over a user's
/// connection nor inherit its persistent subscriptions by reusing its id. The id
/// rumqttd sees is `hex(username):client_id` (injective: hex has no `:`; none of
/// `+$#/`, which rumqttd refuses). An empty id stays empty (rumqttd assigns one).
fn namespaced(username: &str, client_id: &str) -> String {
    if client_id.is_empty() {
        return String::new();
    }
    let hex: String = username.bytes().map(|b| format!("{b:02x}")).collect();
    format!("{hex}:{client_id}")
}

/// The filter of a `$share/{group}/{filter}` subscription, else `filter`.
fn shared_filter(filter: &str) -> &str {
    filter
        .strip_prefix("$share/")
        .and_then(|rest| rest.split_once('/'))
        .map_or(filter, |(_, f)| f)
}

/// Sends a refusing CONNACK (best effort: the client may be gone).
async fn connack<W: AsyncWrite + Unpin>(w: &mut W, code: ConnectReturnCode) {
    let mut out = BytesMut::new();
    let ack = ConnAck {
        session_present: false,
        code,
    };
    if V4.write(Packet::ConnAck(ack, None), &mut out).is_ok() {
        let _ = w.write_all(&out).await;
        let _ = w.shutdown().await;
    }
}

/// The next whole MQTT packet from `r` (bytes as received), `None` at a clean end
/// of stream, `Err` on a framing error or an oversized packet.
async fn read_frame<R: AsyncRead + Unpin>(
    r: &mut R,
    buf: &mut BytesMut,
    max_packet: usize,
) -> Result<Option<BytesMut>, String> {
    loop {
        match v4::check(buf.iter(), max_packet) {
            Ok(header) => return Ok(Some(buf.split_to(header.frame_length()))),
            Err(ProtoError::InsufficientBytes(_)) => {}
            Err(e) => return Err(e.to_string()),
        }
        match r.read_buf(buf).await {
            Ok(0) if buf.is_empty() => return Ok(None),
            Ok(0) => return Err("connection closed inside a packet".into()),
            Ok(_) => {}
            Err(_) => return Ok(None),
        }
    }
}

/// Equal bytes, compared without an early exit.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// 32 random bytes from the kernel, as hex: the internal password.
pub fn make_secret() -> std::io::Result<String> {
    let mut bytes = [0u8; 32];
    let mut urandom = std::fs::File::open("/dev/urandom")?;
    std::io::Read::read_exact(&mut urandom, &mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn client_ids_live_in_their_users_namespace() {
        assert_eq!(namespaced("gw", "dev"), "6777:dev");
        assert_ne!(namespaced("ab", "x"), namespaced("a", "62:x"));
        assert_eq!(namespaced("gw", ""), "");
        assert_eq!(shared_filter("$share/g/thing/#"), "thing/#");
        assert_eq!(shared_filter("thing/#"), "thing/#");
    }

    #[test]
    fn passwords_compare_whole() {
        assert!(constant_time_eq(b"s3cret", b"s3cret"));
        assert!(!constant_time_eq(b"s3cret", b"s3creT"));
        assert!(!constant_time_eq(b"s3cret", b"s3cre"));
    }

    #[test]
    fn secrets_are_random_hex() {
        let (a, b) = (
            make_secret().expect("urandom"),
            make_secret().expect("urandom"),
        );
        assert_eq!(a.len(), 64);
        assert_ne!(a, b);
    }

    #[test]
    fn every_reason_is_distinct() {
        let mut r = reason::ALL.to_vec();
        r.sort_unstable();
        r.dedup();
        assert_eq!(r.len(), reason::ALL.len());
    }
}
