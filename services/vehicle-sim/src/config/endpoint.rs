//! Where the simulator listens: `tcp:IP:PORT` or `udp:IP:PORT`.

use std::net::SocketAddr;

use super::ConfigError;

/// Where the simulator listens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// Serve MAVLink over TCP; every accepted client is its own link.
    Tcp(SocketAddr),
    /// Serve MAVLink over UDP; every peer that has sent a packet gets the telemetry.
    Udp(SocketAddr),
}

impl Endpoint {
    /// The socket address to bind.
    pub fn addr(&self) -> SocketAddr {
        match self {
            Endpoint::Tcp(a) | Endpoint::Udp(a) => *a,
        }
    }
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Endpoint::Tcp(a) => write!(f, "tcp:{a}"),
            Endpoint::Udp(a) => write!(f, "udp:{a}"),
        }
    }
}

/// Parse `tcp:IP:PORT` / `udp:IP:PORT` (`tcpin:`/`udpin:` accepted as synonyms,
/// as the mavlink crate spells listening endpoints).
pub fn parse_endpoint(value: &str) -> Result<Endpoint, ConfigError> {
    let err = |reason: &str| ConfigError::Endpoint {
        value: value.to_owned(),
        reason: reason.to_owned(),
    };
    let (scheme, rest) = value.split_once(':').ok_or_else(|| err("missing scheme"))?;
    let addr: SocketAddr = rest
        .parse()
        .map_err(|_| err("address must be a literal IP:PORT"))?;
    match scheme {
        "tcp" | "tcpin" => Ok(Endpoint::Tcp(addr)),
        "udp" | "udpin" => Ok(Endpoint::Udp(addr)),
        "tcpout" | "udpout" => Err(err("the simulator listens; use tcp: or udp:")),
        _ => Err(err("unknown scheme")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints() {
        assert_eq!(
            parse_endpoint("udp:127.0.0.1:14560"),
            Ok(Endpoint::Udp(SocketAddr::from(([127, 0, 0, 1], 14560))))
        );
        assert!(matches!(
            parse_endpoint("tcpin:[::1]:5760"),
            Ok(Endpoint::Tcp(_))
        ));
        for bad in [
            "127.0.0.1:5760",
            "tcp:localhost:5760",
            "udpout:1.2.3.4:5",
            "serial:/dev/tty",
            "tcp:127.0.0.1",
        ] {
            assert!(parse_endpoint(bad).is_err(), "{bad} should be rejected");
        }
    }
}
