//! The metrics of solo-gateway, exported through the runtime's stats sample.
//!
//! Label sets are bounded: message types are the `solo-proto` names of the known
//! types or `unknown`, malformed kinds are [`Malformed`]. Labelled series are
//! registered on first use: a service has 384 series in its stats sample, and the
//! protocol has ~60 types in two directions.

use skymesh_runtime::{CounterFamily, Gauge, Stats};

/// Why input from the app was dropped (label `kind` of `skymesh_solo_malformed_total`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Malformed {
    /// Declared value length above 64 KiB: the connection is closed.
    TooLong,
    /// The value's length is not the type's length: the frame is dropped.
    WrongLength,
    /// A type id the protocol does not have: ignored.
    UnknownType,
    /// A value that decodes but is out of range (NaN, unknown enum value, bad JSON).
    InvalidValue,
    /// A message only the vehicle sends, arriving from the app.
    WrongDirection,
    /// Part of a frame, then nothing for `frame_timeout_s`: the connection is closed.
    Stalled,
    /// The app stopped reading and its outgoing queue filled: the connection is closed.
    Overflow,
    /// A valid value longer than the bus carries (GEOFENCE_SET_DATA JSON): answered.
    TooLargeForBus,
    /// A follow-stream datagram that is not exactly one LOCATION frame.
    BadDatagram,
    /// A follow-stream datagram from another address than the connected app's.
    Unauthorised,
    /// A follow-stream datagram while no app is connected.
    NoApp,
    /// A frame beyond the app's `max_messages_per_s`/`message_burst`: dropped.
    RateLimited,
    /// A follow-stream datagram beyond `follow_max_per_s`: dropped.
    FollowRateLimited,
    /// A request the shot engine answers, while no shot engine read the bus for
    /// `backend_wait_ms`: answered by the gateway with the protocol's error.
    BackendMissing,
}

impl Malformed {
    pub const ALL: [Malformed; 14] = [
        Malformed::TooLong,
        Malformed::WrongLength,
        Malformed::UnknownType,
        Malformed::InvalidValue,
        Malformed::WrongDirection,
        Malformed::Stalled,
        Malformed::Overflow,
        Malformed::TooLargeForBus,
        Malformed::BadDatagram,
        Malformed::Unauthorised,
        Malformed::NoApp,
        Malformed::RateLimited,
        Malformed::FollowRateLimited,
        Malformed::BackendMissing,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Malformed::TooLong => "too_long",
            Malformed::WrongLength => "wrong_length",
            Malformed::UnknownType => "unknown_type",
            Malformed::InvalidValue => "invalid_value",
            Malformed::WrongDirection => "wrong_direction",
            Malformed::Stalled => "stalled",
            Malformed::Overflow => "overflow",
            Malformed::TooLargeForBus => "too_large_for_bus",
            Malformed::BadDatagram => "bad_datagram",
            Malformed::Unauthorised => "unauthorised",
            Malformed::NoApp => "no_app",
            Malformed::RateLimited => "rate_limited",
            Malformed::FollowRateLimited => "follow_rate_limited",
            Malformed::BackendMissing => "backend_missing",
        }
    }

    /// The kind of a `solo-proto` decode error.
    pub fn from_decode(e: &solo_proto::DecodeError) -> Malformed {
        match e {
            solo_proto::DecodeError::UnknownType(_) => Malformed::UnknownType,
            solo_proto::DecodeError::WrongLength { .. } => Malformed::WrongLength,
            solo_proto::DecodeError::InvalidValue { .. } => Malformed::InvalidValue,
        }
    }
}

/// Which way a message went (label `direction`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// From the app.
    In,
    /// To the app.
    Out,
}

impl Direction {
    fn as_str(self) -> &'static str {
        match self {
            Direction::In => "in",
            Direction::Out => "out",
        }
    }
}

/// How a connection attempt ended (label `result`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ConnectionResult {
    Accepted,
    /// The same address connected again; the old connection was closed.
    Replaced,
    /// Another address while an app is connected: SECOND_PHONE_NOTIFICATION, closed.
    RejectedSecondPhone,
}

impl ConnectionResult {
    fn as_str(self) -> &'static str {
        match self {
            ConnectionResult::Accepted => "accepted",
            ConnectionResult::Replaced => "replaced",
            ConnectionResult::RejectedSecondPhone => "rejected_second_phone",
        }
    }
}

/// Why a message from the shot engine was not written to the app (label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ToAppDrop {
    /// No app is connected.
    NoApp,
    /// Addressed to a session that is no longer the connected one.
    StaleSession,
    /// Its value does not decode as the type it claims (a bug in the sender).
    Invalid,
}

impl ToAppDrop {
    fn as_str(self) -> &'static str {
        match self {
            ToAppDrop::NoApp => "no_app",
            ToAppDrop::StaleSession => "stale_session",
            ToAppDrop::Invalid => "invalid",
        }
    }
}

/// The metric label of a message type: its `solo-proto` name, or `unknown`.
pub fn type_label(msg_type: u32) -> &'static str {
    solo_proto::message_name(msg_type).unwrap_or("unknown")
}

/// Every series solo-gateway exports. Cheap to clone; shared by every task.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_solo_clients_connected`: 1 while an app is connected.
    pub clients_connected: Gauge,
    connections: CounterFamily,
    messages: CounterFamily,
    malformed: CounterFamily,
    follow: CounterFamily,
    to_app_dropped: CounterFamily,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        Metrics {
            clients_connected: stats.gauge("skymesh_solo_clients_connected", &[]),
            connections: CounterFamily::new(
                stats,
                "skymesh_solo_connections_total",
                ("result", None),
            ),
            messages: CounterFamily::new(
                stats,
                "skymesh_solo_messages_total",
                ("direction", Some("type")),
            ),
            malformed: CounterFamily::new(stats, "skymesh_solo_malformed_total", ("kind", None)),
            follow: CounterFamily::new(
                stats,
                "skymesh_solo_follow_datagrams_total",
                ("result", None),
            ),
            to_app_dropped: CounterFamily::new(
                stats,
                "skymesh_solo_to_app_dropped_total",
                ("reason", None),
            ),
        }
    }

    pub fn connection(&self, result: ConnectionResult) {
        self.connections.get(result.as_str(), "").inc();
    }

    /// One valid message from the app (`In`) or written to the app (`Out`).
    pub fn message(&self, direction: Direction, msg_type: u32) {
        self.messages
            .get(direction.as_str(), type_label(msg_type))
            .inc();
    }

    pub fn malformed(&self, kind: Malformed) {
        self.malformed.get(kind.as_str(), "").inc();
    }

    /// One follow-stream datagram, forwarded to the engine or not.
    pub fn follow_datagram(&self, forwarded: bool) {
        let result = if forwarded { "forwarded" } else { "dropped" };
        self.follow.get(result, "").inc();
    }

    pub fn to_app_dropped(&self, reason: ToAppDrop) {
        self.to_app_dropped.get(reason.as_str(), "").inc();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn labels_are_bounded_and_series_registered_on_use() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.message(Direction::In, solo_proto::ids::SET_CURRENT_SHOT);
        m.message(Direction::In, 4242);
        m.message(Direction::In, 777_777);
        m.malformed(Malformed::Stalled);
        m.connection(ConnectionResult::RejectedSecondPhone);
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        let msgs = "skymesh_solo_messages_total";
        let set_shot = format!(
            "direction=in,type={}",
            type_label(solo_proto::ids::SET_CURRENT_SHOT)
        );
        assert_eq!(find(msgs, &set_shot), Some(1.0));
        assert_eq!(find(msgs, "direction=in,type=unknown"), Some(2.0));
        assert_eq!(
            find("skymesh_solo_malformed_total", "kind=stalled"),
            Some(1.0)
        );
        assert_eq!(
            find("skymesh_solo_malformed_total", "kind=overflow"),
            None,
            "registered on first use"
        );
        assert_eq!(
            find(
                "skymesh_solo_connections_total",
                "result=rejected_second_phone"
            ),
            Some(1.0)
        );
        assert_eq!(find("skymesh_solo_clients_connected", ""), Some(0.0));
    }

    #[test]
    fn kind_names_are_distinct() {
        let mut names: Vec<_> = Malformed::ALL.iter().map(|k| k.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Malformed::ALL.len());
    }
}
