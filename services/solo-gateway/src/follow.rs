//! The follow stream: during the Follow shot the app sends its position as one
//! LOCATION datagram (TLV type 2, 20-byte value) at about 25 Hz. Only the connected
//! app's address is listened to; each good datagram is forwarded to the engine
//! (flagged `FOLLOW_STREAM`), which uses the newest one per tick.

use std::net::{IpAddr, SocketAddr};

use skymesh_runtime::TokenBucket;
use solo_proto::SoloMessage;
use tokio::net::UdpSocket;
use tokio::sync::watch;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::drops::Drops;
use crate::hub::AppAddr;
use crate::ipc::{FromApp, PublishError};
use crate::metrics::Malformed;

/// Larger than any valid datagram (28 bytes); a longer one is cut here and refused.
const DATAGRAM_BUF: usize = 2048;

/// Checks one datagram (pure): the session to forward it under, or why not.
pub fn check(
    datagram: &[u8],
    from: IpAddr,
    app: Option<AppAddr>,
) -> Result<u32, (Malformed, String)> {
    let Some(app) = app else {
        return Err((Malformed::NoApp, "no app is connected".to_string()));
    };
    if from.to_canonical() != app.ip {
        return Err((
            Malformed::Unauthorised,
            format!("not from the connected app's address {}", app.ip),
        ));
    }
    match solo_proto::decode_datagram(datagram) {
        Ok(m @ SoloMessage::Location(_)) => match crate::inbound::magnitudes(&m) {
            Ok(()) => Ok(app.session),
            Err(reason) => Err((Malformed::BadDatagram, reason)),
        },
        Ok(other) => Err((
            Malformed::BadDatagram,
            format!(
                "{} (type {}) is not a LOCATION",
                other.name(),
                other.msg_type()
            ),
        )),
        Err(e) => Err((Malformed::BadDatagram, e.to_string())),
    }
}

/// Receives follow datagrams until `stop`; returns an error only if the bus fails.
/// Good datagrams beyond `max_per_s` (one bucket of as many, for the app's address:
/// no other address gets this far) are dropped and counted `follow_rate_limited`.
pub(crate) async fn run(
    socket: UdpSocket,
    app: watch::Receiver<Option<AppAddr>>,
    from_app: FromApp,
    drops: Drops,
    max_per_s: u32,
    stop: CancellationToken,
) -> Result<(), PublishError> {
    let mut buf = vec![0u8; DATAGRAM_BUF];
    let mut rate = TokenBucket::new(max_per_s, max_per_s, Instant::now().into_std());
    loop {
        let (n, from): (usize, SocketAddr) = tokio::select! {
            _ = stop.cancelled() => return Ok(()),
            r = socket.recv_from(&mut buf) => match r {
                Ok(v) => v,
                Err(e) => {
                    tracing::debug!(error = %e, "follow stream receive failed");
                    continue;
                }
            },
        };
        let datagram = &buf[..n];
        let current = *app.borrow();
        match check(datagram, from.ip(), current) {
            Ok(_) if !rate.take(Instant::now().into_std()) => {
                drops.metrics().follow_datagram(false);
                drops.record(
                    Malformed::FollowRateLimited,
                    from,
                    &format_args!("more than {max_per_s} follow datagrams per second"),
                );
            }
            Ok(session) => {
                // `check` accepted a LOCATION: it decodes, and has a request.
                if let Some(request) = solo_proto::decode_datagram(datagram)
                    .ok()
                    .as_ref()
                    .and_then(crate::translate::request)
                {
                    from_app.publish(session, &request, true)?;
                }
                drops.metrics().follow_datagram(true);
            }
            Err((kind, reason)) => {
                drops.metrics().follow_datagram(false);
                drops.record(kind, from, &reason);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use solo_proto::Location;

    fn location() -> Vec<u8> {
        SoloMessage::Location(Location {
            lat_deg: 37.8,
            lon_deg: -122.3,
            alt_m: 1.5,
        })
        .to_bytes()
        .to_vec()
    }

    #[test]
    fn only_the_connected_apps_locations_pass() {
        let app_ip: IpAddr = "127.0.0.1".parse().unwrap();
        let other: IpAddr = "127.0.0.2".parse().unwrap();
        let app = Some(AppAddr {
            session: 7,
            ip: app_ip,
        });
        assert_eq!(check(&location(), app_ip, app), Ok(7));
        assert_eq!(
            check(&location(), "::ffff:127.0.0.1".parse().unwrap(), app),
            Ok(7)
        );
        assert_eq!(
            check(&location(), other, app).unwrap_err().0,
            Malformed::Unauthorised
        );
        assert_eq!(
            check(&location(), app_ip, None).unwrap_err().0,
            Malformed::NoApp
        );
        let mut long = location();
        long.push(0);
        assert_eq!(
            check(&long, app_ip, app).unwrap_err().0,
            Malformed::BadDatagram
        );
        assert_eq!(
            check(&location()[..20], app_ip, app).unwrap_err().0,
            Malformed::BadDatagram
        );
        let pause = SoloMessage::Pause.to_bytes();
        assert_eq!(
            check(&pause, app_ip, app).unwrap_err().0,
            Malformed::BadDatagram
        );
    }
}
